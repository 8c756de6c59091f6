"""Source patches as edits at anchors that must be found, so an upstream change fails the image build with
the file and the anchor named instead of silently producing a mis-patched binary. Run by the images'
python3 (Debian 12: Python 3.11)."""
import os
import re
import sys


def _read(root, path):
    full = os.path.join(root, path)
    if not os.path.isfile(full):
        sys.exit("patch: %s: file not found in %s (did upstream change?)" % (path, root))
    with open(full, encoding="utf-8", errors="surrogateescape") as f:
        return full, f.read()


def _write(full, text):
    with open(full, "w", encoding="utf-8", errors="surrogateescape") as f:
        f.write(text)


def patch(root, path, where, anchor, text):
    """Insert `text` before/after `anchor`, or replace it; the anchor must occur exactly once."""
    full, src = _read(root, path)
    count = src.count(anchor)
    if count != 1:
        sys.exit("patch: %s: anchor %r found %d times, expected once (did upstream change?)" % (path, anchor, count))
    if where == "before":
        src = src.replace(anchor, text + anchor)
    elif where == "after":
        src = src.replace(anchor, anchor + text)
    elif where == "replace":
        src = src.replace(anchor, text)
    else:
        sys.exit("patch: where must be before, after or replace")
    _write(full, src)
    print("patch: %s (%s %r)" % (path, where, anchor[:50]))


def sub(root, path, pattern, repl, min_count=1):
    """Regular-expression substitution that must match at least `min_count` times; returns the count."""
    full, src = _read(root, path)
    new, n = re.subn(pattern, repl, src)
    if n < min_count:
        sys.exit("patch: %s: %r matched %d times, expected at least %d (did upstream change?)"
                 % (path, pattern, n, min_count))
    _write(full, new)
    print("patch: %s (%d x %r)" % (path, n, pattern[:50]))
    return n


def append_line(root, path, line):
    """Append a line, adding the newline the file may lack at its end."""
    full, src = _read(root, path)
    if src and not src.endswith("\n"):
        src += "\n"
    _write(full, src + line + "\n")
    print("patch: %s (+%r)" % (path, line[:50]))


def include_once(root, path, header):
    """Add an #include at the top of a file unless it is there."""
    full, src = _read(root, path)
    line = "#include <%s>\n" % header
    if line not in src:
        _write(full, line + src)
        print("patch: %s (+%s)" % (path, header))


# OpenCV 4 dropped the C API's constants; their C++ names exist since OpenCV 2.4/3.
OPENCV4 = [
    (r"\bCV_LOAD_IMAGE_(GRAYSCALE|UNCHANGED|COLOR|ANYDEPTH)\b", r"cv::IMREAD_\1"),
    (r"\bCV_(BGR2GRAY|RGB2GRAY|GRAY2BGR|GRAY2RGB|BGR2RGB|RGB2BGR|BGRA2GRAY|RGBA2GRAY|GRAY2BGRA)\b", r"cv::COLOR_\1"),
    (r"\bCV_WINDOW_(AUTOSIZE|NORMAL)\b", r"cv::WINDOW_\1"),
    (r"\bCV_INTER_(LINEAR|NN|CUBIC|AREA)\b", lambda m: "cv::INTER_" + {"NN": "NEAREST"}.get(m.group(1), m.group(1))),
    (r"\bCV_FONT_HERSHEY_(\w+)\b", r"cv::FONT_HERSHEY_\1"),
    (r"\bCV_AA\b", "cv::LINE_AA"),
    (r"\bCV_TERMCRIT_(ITER|EPS)\b", r"cv::TermCriteria::\1"),
    (r"\bCV_REDUCE_(SUM|AVG|MAX|MIN)\b", r"cv::REDUCE_\1"),
    (r"\bCV_CAP_PROP_(\w+)\b", r"cv::CAP_PROP_\1"),
    (r"\bCV_SORT_(EVERY_ROW|EVERY_COLUMN|ASCENDING|DESCENDING)\b", r"cv::SORT_\1"),
]


def opencv4(root, subdirs=("src",), exts=(".cpp", ".cc", ".h", ".hpp"), min_count=1):
    """Replace the removed OpenCV C constants by their C++ names in every source file below `subdirs`."""
    total = 0
    for sd in subdirs:
        for dirpath, _, files in os.walk(os.path.join(root, sd)):
            for name in sorted(files):
                if not name.endswith(exts):
                    continue
                full = os.path.join(dirpath, name)
                with open(full, encoding="utf-8", errors="surrogateescape") as f:
                    src = f.read()
                n_file = 0
                for pattern, repl in OPENCV4:
                    src, n = re.subn(pattern, repl, src)
                    n_file += n
                if n_file:
                    _write(full, src)
                    total += n_file
    if total < min_count:
        sys.exit("patch: no OpenCV C constant found below %s in %s (did upstream change?)" % (", ".join(subdirs), root))
    print("patch: %d OpenCV constant(s) updated below %s" % (total, ", ".join(subdirs)))
    return total


def cxx_standard(root, path, old, new="-std=c++14"):
    """Raise the C++ standard a CMakeLists asks for (gcc 12 + Boost 1.74/Eigen 3.4 need at least C++14)."""
    return sub(root, path, re.escape(old), new)
