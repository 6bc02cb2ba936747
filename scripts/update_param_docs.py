#!/usr/bin/env python3
"""Regenerate the parameter tables in docs/ from the plugins' declared specs.

Every block
    <!-- loom-params: NAME -->
    ...
    <!-- /loom-params -->
in docs/plugins/*.md, docs/RENDERING.md and docs/SCENE_KEYS.md (the framework's own sections) is replaced by the output of
`loom plugins --params NAME --markdown` (tests/param_spec checks that they match).

usage: scripts/update_param_docs.py [LOOM_BINARY]   (default: build/bin/loom)
"""
import pathlib
import re
import subprocess
import sys

root = pathlib.Path(__file__).resolve().parent.parent
loom = sys.argv[1] if len(sys.argv) > 1 else str(root / "build" / "bin" / "loom")
files = sorted((root / "docs" / "plugins").glob("*.md")) + [root / "docs" / "RENDERING.md", root / "docs" / "SCENE_KEYS.md"]
block = re.compile(r"(<!-- loom-params: ([a-z0-9_]+) -->\n)(.*?)(<!-- /loom-params -->)", re.S)

changed = 0
for f in files:
    text = f.read_text()

    def table(m):
        name = m.group(2)
        r = subprocess.run([loom, "plugins", "--params", name, "--markdown"], capture_output=True, text=True)
        if r.returncode != 0:
            print(f"{f.name}: {name}: not in this build, left as is ({r.stderr.strip()})", file=sys.stderr)
            return m.group(0)
        return m.group(1) + r.stdout + m.group(4)

    new = block.sub(table, text)
    if new != text:
        f.write_text(new)
        changed += 1
        print(f"updated {f.relative_to(root)}")
print(f"{changed} file(s) changed")
