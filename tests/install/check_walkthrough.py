#!/usr/bin/env python3
"""docs/ADD_A_PLUGIN.md shows the toy plugin's files verbatim: each fenced block after a
`<!-- file: PATH -->` marker must equal the file PATH (relative to the source tree), and every
file of tests/install/toy_plugin must be shown. usage: check_walkthrough.py SOURCE_DIR"""
import pathlib
import re
import sys

root = pathlib.Path(sys.argv[1])
doc = (root / "docs" / "ADD_A_PLUGIN.md").read_text()
blocks = re.findall(r"<!-- file: (\S+) -->\n```[a-z]*\n(.*?)```", doc, re.S)
shown = set()
bad = 0
for path, text in blocks:
    shown.add(path)
    actual = (root / path).read_text()
    if text != actual:
        print(f"docs/ADD_A_PLUGIN.md: the block of {path} differs from the file. Fix: paste the file into the block.")
        bad += 1
for f in sorted((root / "tests" / "install" / "toy_plugin").iterdir()):
    rel = str(f.relative_to(root))
    if rel not in shown:
        print(f"docs/ADD_A_PLUGIN.md does not show {rel}")
        bad += 1
if not blocks:
    print("docs/ADD_A_PLUGIN.md: no <!-- file: ... --> blocks")
    bad += 1
print(f"{len(blocks)} block(s) checked, {bad} problem(s)")
sys.exit(1 if bad else 0)
