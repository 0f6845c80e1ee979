#!/usr/bin/env python3
"""Every code listing that the docs mark as an excerpt of a file is that file's text, verbatim.

A listing is marked by the line `<!-- listing: PATH -->` (PATH from the repository's root) right
before its fence; it must occur in PATH as one contiguous piece. A listing that was pasted once
and then drifted from its program (the program changed, the docs did not) fails, naming the page,
the file and the first line of the listing that the file does not have.

    python3 tests/doc_listings.py REPOSITORY
"""
import pathlib
import re
import sys

MARKED = re.compile(r"^<!-- listing: (\S+) -->\n```[A-Za-z0-9]*\n(.*?)^```", re.M | re.S)


def first_missing_line(listing: str, source: str) -> str:
    """The first line of `listing` whose text, with every line before it, is not in `source`."""
    lines = listing.splitlines(keepends=True)
    for end in range(1, len(lines) + 1):
        if "".join(lines[:end]) not in source:
            return lines[end - 1].rstrip("\n")
    return ""


def main() -> int:
    if len(sys.argv) != 2:
        print("usage: doc_listings.py REPOSITORY", file=sys.stderr)
        return 2
    root = pathlib.Path(sys.argv[1])
    pages = [root / "README.md", *sorted((root / "docs").glob("**/*.md"))]
    problems, checked = [], 0
    for page in (p for p in pages if p.is_file()):
        text = page.read_text(encoding="utf-8")
        for match in MARKED.finditer(text):
            checked += 1
            where = f"{page.relative_to(root)}:{text.count(chr(10), 0, match.start()) + 1}"
            source_path = root / match.group(1)
            if not source_path.is_file():
                problems.append(f"  {where}: its listing names {match.group(1)}, which does not exist")
                continue
            listing, source = match.group(2), source_path.read_text(encoding="utf-8")
            if listing not in source:
                problems.append(f"  {where}: its listing is not in {match.group(1)}; the first line "
                                f"that differs: '{first_missing_line(listing, source)}'")
    if problems:
        print("listings that are not their file's text:\n" + "\n".join(problems))
        return 1
    if checked == 0:
        print(f"no marked listing found under {root}: expected at least one")
        return 1
    print(f"doc listings: {checked}, each its file's text")
    return 0


if __name__ == "__main__":
    sys.exit(main())
