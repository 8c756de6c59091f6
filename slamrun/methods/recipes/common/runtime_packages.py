"""The Debian packages a runtime stage needs: those owning the shared libraries the given binaries load.

usage: runtime_packages.py BINARY... > packages.txt
Libraries under /usr/local or /opt are the image's own (copied, not installed). An unresolved library
fails the build, naming it.
"""
import os
import re
import subprocess
import sys

libs, missing = set(), []
for binary in sys.argv[1:]:
    out = subprocess.run(["ldd", binary], capture_output=True, text=True, check=True).stdout
    for line in out.splitlines():
        if "not found" in line:
            missing.append("%s: %s" % (binary, line.strip()))
        m = re.search(r"=> (/\S+)", line)
        if m:
            libs.add(m.group(1))
if missing:
    sys.exit("runtime_packages: unresolved libraries:\n  " + "\n  ".join(missing))
packages = set()
for lib in sorted(libs):
    if lib.startswith(("/usr/local/", "/opt/")):
        continue
    candidates = {lib, os.path.realpath(lib)}
    candidates |= {"/usr" + c for c in list(candidates) if not c.startswith("/usr/")}
    candidates |= {c[4:] for c in list(candidates) if c.startswith("/usr/")}
    for path in sorted(candidates):
        res = subprocess.run(["dpkg", "-S", path], capture_output=True, text=True)
        if res.returncode == 0:
            packages.add(res.stdout.split(":")[0].split(",")[0].strip())
            break
    else:
        sys.exit("runtime_packages: no Debian package owns %s" % lib)
print("\n".join(sorted(packages)))
