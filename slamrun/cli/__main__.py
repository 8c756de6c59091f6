from slamrun.cli import main

raise SystemExit(main())
