"""The TUM-Mono benchmark's own evaluator (tum-vision/mono_dataset_code, MatlabEvaluationCode/) run under GNU Octave,
beside slamrun's: for the exactness test (tests/test_official_evaluator.py) and the speed ratio of `make bench`.

The code is taken from its pinned archive (slamrun/images/sources.py: `mono_dataset_code`), unpacked once. Octave
lacks MATLAB's `dcm2quat`: a shim gives the quaternion of a rotation matrix (w first); efficientEvalDrift uses
only its w (e_r = 2 acos(w)), which is the same for a matrix and its transpose.
"""

from __future__ import annotations

import shutil
import subprocess
import tarfile
from pathlib import Path

from slamrun.images.sources import SOURCES, obtain

DCM2QUAT = """function q = dcm2quat(R)
  % quaternion [w x y z] of a rotation matrix (Octave has no dcm2quat)
  w = sqrt(max(0, 1 + trace(R))) / 2;
  x = sqrt(max(0, 1 + R(1,1) - R(2,2) - R(3,3))) / 2;
  y = sqrt(max(0, 1 - R(1,1) + R(2,2) - R(3,3))) / 2;
  z = sqrt(max(0, 1 - R(1,1) - R(2,2) + R(3,3))) / 2;
  q = [w x y z];
end
"""

# Evaluates every file of a list against one groundtruthSync.txt, one line per file:
# file rmse errAlign errR errS abserrA abserrE nkf norm(T_drift translation)
DRIVER = """function evaluate_list(gt_file, list_file, out_file)
  sequence = struct();
  sequence.name = 'sequence';
  sequence.mocapRaw = importdata(gt_file);
  files = strsplit(fileread(list_file), "\\n");
  out = fopen(out_file, 'w');
  for k = 1:numel(files)
    f = strtrim(files{k});
    if isempty(f)
      continue;
    end
    [rmse, errTrafo, errAlign, errR, errS, abserrA, abserrE, nkf] = efficientEvalDrift(f, sequence, 0);
    fprintf(out, '%s %.17g %.17g %.17g %.17g %.17g %.17g %d %.17g\\n', f, rmse, errAlign, errR, errS, ...
            abserrA, abserrE, nkf, norm(errTrafo(1:3, 4)));
  end
  fclose(out);
end
"""
FIELDS = ("e_rmse", "e_align", "e_r", "e_s", "e_start", "e_end", "n_poses", "e_t")


def octave() -> str | None:
    """The path of octave-cli, or None when Octave is not installed (Debian: apt-get install octave)."""
    return shutil.which("octave-cli") or shutil.which("octave")


def evaluator_dir(work: Path, sources_dir: Path | None = None) -> Path:
    """The official MATLAB evaluation code from the pinned archive, with the dcm2quat shim and the list driver."""
    source = SOURCES["mono_dataset_code"]
    folder = work / source.top / "MatlabEvaluationCode"
    if not (folder / "evaluate_list.m").exists():
        archive = obtain(source.name, sources_dir)
        with tarfile.open(archive) as tar:
            tar.extractall(work, filter="data")
        (folder / "dcm2quat.m").write_text(DCM2QUAT)
        (folder / "evaluate_list.m").write_text(DRIVER)
    return folder


def command(folder: Path, gt: Path, files: list[Path], work: Path) -> tuple[list[str], Path]:
    """The whole-process command that evaluates `files` with the official code, and the file it writes."""
    listing, out = work / "official-files.txt", work / "official-results.txt"
    listing.write_text("".join(f"{Path(f).resolve()}\n" for f in files))
    call = f"evaluate_list('{Path(gt).resolve()}', '{listing}', '{out}')"
    return [octave() or "octave-cli", "--no-gui", "--quiet", "--no-window-system", "--eval", call], out


def evaluate(gt: Path, files: list[Path], work: Path, sources_dir: Path | None = None) -> dict[str, dict]:
    """The official figures of each file: {file: {e_rmse, e_align, e_r, e_s, e_start, e_end, n_poses, e_t}}."""
    folder = evaluator_dir(work, sources_dir)
    argv, out = command(folder, gt, files, work)
    subprocess.run(argv, cwd=folder, check=True, capture_output=True, text=True, timeout=3600)
    results = {}
    for line in out.read_text().splitlines():
        name, *values = line.split()
        results[name] = {k: float(v) for k, v in zip(FIELDS, values, strict=True)}
    return results
