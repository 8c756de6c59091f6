"""slamrun images and list-methods: the methods, and building and verifying their Docker images."""

from __future__ import annotations

import json
from pathlib import Path

from slamrun.cli.console import console
from slamrun.errors import SlamRunError


def add_commands(sub) -> None:
    lm = sub.add_parser("list-methods", help="the registered methods")
    lm.add_argument("--json", action="store_true", help="as JSON, for scripts (image, GPU, pinned archives)")
    lm.set_defaults(func=cmd_list_methods)
    im = sub.add_parser("images", help="build (and verify) the methods' Docker images")
    im.add_argument("--method", action="append", help="only this method (repeatable)")
    im.add_argument("--list", action="store_true", help="list the buildable images and exit")
    im.add_argument("--sources", type=Path, help="folder of upstream source archives (no network needed)")
    im.add_argument("--source-url", help="base address of the source archives (default https://github.com)")
    im.add_argument("--march", default="x86-64-v2", help="-march target the methods are compiled for")
    im.add_argument("--jobs", type=int, help="parallel compile jobs (default: all cores)")
    im.add_argument(
        "--vocabulary", action="append", default=[], metavar="[METHOD=]FILE", help="a vocabulary file for the build"
    )
    im.add_argument(
        "--weights",
        action="append",
        default=[],
        metavar="NAME=FILE",
        help="weights for the build: a file, or URL#sha256=HEX",
    )
    im.add_argument(
        "--no-train-vocabulary", action="store_true", help="fail instead of training a vocabulary the source lacks"
    )
    im.add_argument(
        "--standin-model",
        action="store_true",
        help="without --weights: an untrained stand-in network (CNN-DSO, CNN-SVO, DynaSLAM), for plumbing tests only",
    )
    im.add_argument("--build-arg", action="append", default=[], metavar="KEY=VALUE", help="extra Docker build argument")
    im.add_argument("--log-dir", type=Path, help="where build logs and records go (default .cache/images)")
    im.add_argument("--missing", action="store_true", help="build only the images that do not exist yet")
    im.add_argument("--no-cache", action="store_true", help="rebuild every step (a from-scratch build time)")
    im.add_argument(
        "--verify",
        action="store_true",
        help="build what is missing, run a short Docker campaign per image, print a table of results",
    )
    im.add_argument(
        "--results", type=Path, help="results folder of --verify (default: .cache/verify under the current directory)"
    )
    im.add_argument(
        "--export",
        type=Path,
        metavar="DIR",
        help="write the built images as archives into DIR, for `podman load -i` on machines without Docker",
    )
    im.set_defaults(func=cmd_images)
    ve = sub.add_parser("verify", help="verify the methods of a spec on the synthetic rooms (any method)")
    ve.add_argument("spec", type=Path, help="a spec: its methods (built-in, plug-in, external) and backend")
    ve.add_argument("--method", action="append", help="only this method label (repeatable)")
    ve.add_argument("--results", type=Path, help="results folder (default: .cache/verify under the current directory)")
    ve.add_argument("--trials", type=int, default=2, help="trials per room and direction")
    ve.add_argument("--frames", type=int, default=300, help="frames of each synthetic room")
    ve.set_defaults(func=cmd_verify)
    nm = sub.add_parser("new-method", help="write a method package of one's own: adapter, Dockerfile, test")
    nm.add_argument("name", help="the method's name (lower case, digits, _)")
    nm.add_argument("--dest", type=Path, help="the package folder to write (default ./slamrun-NAME)")
    nm.set_defaults(func=cmd_new_method)


def cmd_list_methods(args) -> int:
    from rich.table import Table

    import slamrun.methods

    if args.json:
        print(json.dumps(methods_json(), indent=1))
        return 0
    t = Table(title="methods")
    for c in ("name", "view", "image", "gpu", "native", "loop closure switch", "from"):
        t.add_column(c)
    for name, cls in sorted(slamrun.methods.REGISTRY.items()):
        prof = cls.profile if isinstance(cls.profile, str) else getattr(cls.profile, "value", "per spec")
        t.add_row(
            name,
            str(prof),
            cls.image if isinstance(cls.image, str) else "-" if cls.image is None else "from the spec",
            "required" if cls.needs_gpu is True else "optional" if cls.gpu_capable else "no",  # a property: per params
            "yes" if cls.native else "no",
            cls.loop_closure_switch or "-",
            str(slamrun.methods.PLUGINS.get(name, "slamrun")),
        )
    console.print(t)
    for name, why in sorted(slamrun.methods.PLUGIN_ERRORS.items()):
        console.print(f"not registered: {name}: {why}")
    return 0


def methods_json() -> dict:
    """Each method as scripts read it (scripts/gpu-check.sh, gpu-wheels.sh): its image, GPU needs, the file names of
    the pinned archives its image builds from, its native build's (null without one) and its published variants."""
    import slamrun.methods
    from slamrun.images.sources import SOURCES
    from slamrun.methods.declare import declared

    out = {}
    for name, cls in slamrun.methods.REGISTRY.items():
        native = declared(cls, "native_build")
        out[name] = {
            "image": cls.image if isinstance(cls.image, str) else None,
            "gpu": "required" if cls.needs_gpu is True else "optional" if cls.gpu_capable else "no",
            "native": bool(cls.native),
            "archives": [s.filename for s in declared(cls, "sources", ())],
            "native_build": {"archives": [SOURCES[s].filename for s in native.archives]} if native else None,
            "variants": cls.variants,
        }
    return out


def cmd_images(args) -> int:
    import slamrun.methods
    from slamrun.images.build import METHODS, BuildOptions, build, buildable, stage_files

    if args.list:
        for name, (tag, dockerfile) in buildable().items():
            gpu = " (GPU optional, CPU by default)" if slamrun.methods.REGISTRY[name].gpu_capable else ""
            where = dockerfile.relative_to(METHODS) if dockerfile.is_relative_to(METHODS) else dockerfile
            parts = ", ".join(str(path.relative_to(METHODS)) for path in stage_files(dockerfile))
            stages = f" (+ {parts})" if parts else ""
            console.print(f"{name}: {tag} <- {where}{stages}{gpu}")
        return 0
    opts = BuildOptions(
        sources_dir=args.sources,
        source_url=args.source_url,
        march=args.march,
        vocabulary=dict(_pair(v, "*") for v in args.vocabulary),
        weights=dict(_pair(w) for w in args.weights),
        train_vocabulary=not args.no_train_vocabulary,
        standin_model=args.standin_model,
        build_args=dict(_pair(b) for b in args.build_arg),
        no_cache=args.no_cache,
    )
    if args.jobs:
        opts.jobs = args.jobs
    if args.log_dir:
        opts.log_dir = args.log_dir
    if args.export:
        return _export(args.method, args.export)
    if args.verify:
        from slamrun.images.verify import print_table, verify

        rows = verify(args.method, opts, _verify_folder(args.results), log=lambda m: print(m, flush=True))
        print_table(rows, console)
        return 0 if rows and all(r.passed for r in rows) else 1  # 1: a method not verified
    records = build(args.method, log=lambda m: print(m, flush=True), opts=opts, only_missing=args.missing)
    console.print(f"built {len(records)} image(s): {', '.join(r.tag for r in records) or '-'}")
    return 0


def _pair(text: str, default_key: str | None = None) -> tuple[str, Path | str]:
    """KEY=VALUE (or VALUE alone when a default key is allowed)."""
    if "=" in text:
        key, value = text.split("=", 1)
        return key, value
    if default_key is None:
        raise SlamRunError(f"{text!r}: expected KEY=VALUE")
    return default_key, text


def cmd_verify(args) -> int:
    from slamrun.images.verify import print_table, verify_spec

    folder = _verify_folder(args.results)
    rows = verify_spec(args.spec, args.method, folder, lambda m: print(m, flush=True), args.trials, args.frames)
    print_table(rows, console)
    return 0 if rows and all(r.passed for r in rows) else 1  # 1: a method not verified


def _verify_folder(results: Path | None) -> Path:
    """Verify's results folder (--results or the default), checked by the guard of every output folder and marked
    as slamrun's before anything is built or written."""
    from slamrun.engine.folders import VERIFY, claim_output_folder, require_output_folder
    from slamrun.images.verify import DEFAULT_RESULTS

    folder = Path(results or DEFAULT_RESULTS).resolve()
    require_output_folder(folder, VERIFY)
    claim_output_folder(folder, VERIFY)
    return folder


def cmd_new_method(args) -> int:
    from slamrun.images.scaffold import new_method

    dest = args.dest or Path(f"slamrun-{args.name}")
    files = new_method(args.name, dest)
    return next_steps(dest, len(files), [
        (f"pip install -e {dest}", f"registers {args.name} (entry point slamrun.methods)"),
        ("slamrun list-methods", f"{args.name} is listed"),
        (f"pytest {dest}/tests", "its adapter's tests"),
        ("slamrun verify SPEC", "a spec naming it: the verification table on the synthetic rooms"),
    ])  # fmt: skip


def next_steps(dest: Path, n_files: int, steps: list[tuple[str, str]]) -> int:
    """What a scaffold wrote and what to do next: each command with what it does."""
    console.print(f"{dest}: {n_files} files; fill in the lines marked FILL IN, then:")
    width = max(len(command) for command, _ in steps)
    for command, why in steps:
        console.print(f"  {command:<{width}}   # {why}")
    return 0


def _export(only: list[str] | None, dest: Path) -> int:
    from slamrun.backends.docker import DockerBackend
    from slamrun.images.build import buildable
    from slamrun.images.export import export_image

    client = DockerBackend().client
    for name, (tag, _) in buildable().items():
        if only and name not in only:
            continue
        if not only and not client.images.list(name=tag):
            continue  # without --method: the images built here
        path, sha = export_image(client, tag, dest)
        size_mb = path.stat().st_size / 2**20
        console.print(f"{tag} -> {path} ({size_mb:.0f} MB, sha256 {sha}); load it: podman load -i {path}")
    return 0
