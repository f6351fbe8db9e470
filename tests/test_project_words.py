"""The repository speaks of its subject only: no file tells how it was made.

Every file git tracks (text files; images and Parquet parts skipped) is searched for words that
belong to a development narrative rather than to the twin: work periods, tracker numbers, targets
called by the word for a rod, the people or programs who checked a change, and citations of
design notes kept elsewhere. Legitimate uses stay allowed: a subprocess's ``start_new_session``,
a progress or error b[a]r, Matplotlib's ``ax.b[a]r``, B[a]r-Shalom's book, another project's
tracker (``owner/repo`` then a number). Each pattern writes one letter in brackets so this file
does not match itself.
"""

import re
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

PATTERNS = {
    "a work period": re.compile(r"(?<!\w)s[e]ssions?\b", re.IGNORECASE),
    "a tracker reference": re.compile(
        r"\bi[s]sues?(\s*#?\d+|'s)\b|\bthe i[s]sue\b|(?<![\w/&-])#\d{1,5}\b(?!-)", re.IGNORECASE
    ),
    "a target called a b[a]r": re.compile(
        r"(?<!progress )(?<!error )(?<!color )(?<!colour )\bb[a]rs?\b(?![-(])", re.IGNORECASE
    ),
    "a checker of changes": re.compile(r"\br[e]view(ers?|s|ed|ing)?\b", re.IGNORECASE),
    "an assistant": re.compile(r"\bh[e]lpers?\b", re.IGNORECASE),
    "an approval criterion": re.compile(r"\ba[c]ceptance\b", re.IGNORECASE),
    "notes kept elsewhere": re.compile(r"\bD[E]SIGN(\.md| §)"),
}


def _tracked() -> list[Path]:
    out = subprocess.run(
        ["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True, timeout=60
    ).stdout
    return [ROOT / name for name in out.decode().split("\0") if name]


def test_no_tracked_file_tells_how_the_project_was_made():
    hits = []
    for path in _tracked():
        if not path.is_file():
            # a file deleted in the working tree but not yet in the index
            continue
        data = path.read_bytes()
        if b"\0" in data[:8192]:
            continue
        try:
            text = data.decode("utf-8")
        except UnicodeDecodeError:
            continue
        for number, line in enumerate(text.splitlines(), 1):
            for what, pattern in PATTERNS.items():
                if m := pattern.search(line):
                    rel = path.relative_to(ROOT)
                    hits.append(f"{rel}:{number}: {what} ({m.group(0)!r}); say it of the twin")
    assert not hits, "\n".join(hits)
