"""The repository stands alone: no file in it refers to a path outside it."""

import re
import subprocess
from pathlib import Path

ROOT = Path(__file__).parent.parent
# Built from pieces so that this file does not match its own pattern.
OUTSIDE = re.compile("|".join(re.escape(a + b) for a, b in [("../", "shared"), ("/work/", "shared"), ("../", ".library")]))


def tracked_files():
    try:
        names = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True).stdout.split()
    except (OSError, subprocess.CalledProcessError):  # not a git checkout: every file under the root
        names = [str(p.relative_to(ROOT)) for p in ROOT.rglob("*") if p.is_file() and ".git" not in p.parts]
    return [ROOT / n for n in names]


def test_no_file_refers_outside_the_repository():
    offenders = []
    for path in tracked_files():
        try:
            text = path.read_text(encoding="utf-8")
        except (UnicodeDecodeError, OSError):
            continue  # figures and other binary files
        offenders += [f"{path.relative_to(ROOT)}:{text.count(chr(10), 0, m.start()) + 1}" for m in OUTSIDE.finditer(text)]
    assert len(tracked_files()) > 50 and not offenders, offenders
