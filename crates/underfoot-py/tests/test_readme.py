"""The README's Python example runs as written, in a user's clone: a fresh folder where
`../shared/data` is the shared recordings, so that its relative paths resolve and what it
saves lands there, not in the repository."""

import os
import re
import subprocess
import sys

from conftest import REPO


def test_the_readme_python_example_runs_as_written(tmp_path, data_dir):
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    section = readme.split("## From Python", 1)[1].split("\n## ", 1)[0]
    blocks = re.findall(r"```python\n(.*?)```", section, re.S)
    assert blocks, "the README's 'From Python' section has no python block"
    proj = tmp_path / "proj"
    proj.mkdir()
    os.symlink(data_dir.parent.parent, tmp_path / "shared")
    for code in blocks:
        done = subprocess.run(
            [sys.executable, "-c", code], cwd=proj, capture_output=True, text=True, timeout=300
        )
        assert done.returncode == 0, f"README example failed:\n{code}\n{done.stderr}"
    # What it says it saves, it saved: a library the command line reads.
    assert (proj / "materials.json").is_file()
