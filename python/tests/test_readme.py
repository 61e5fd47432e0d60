"""The Python example in README.md runs as written (on the real CT)."""

import os
import re

import numpy as np

from conftest import REPO


def test_the_readme_example_runs(tmp_path, real_ct, monkeypatch):
    text = (REPO / "README.md").read_text()
    section = text.split("## From Python", 1)[1]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    monkeypatch.chdir(tmp_path)
    os.symlink(REPO / "target", tmp_path / "target")
    scope: dict = {}
    exec(compile(code, "README.md", "exec"), scope)
    assert scope["front"].shape == (512, 512, 4) and scope["front"][..., 3].any()
    depth = scope["depth"]
    assert depth.shape == (512, 512) and np.isfinite(depth).any() and np.isnan(depth).any()
    assert scope["codes"].shape == (107, 255, 255)
    assert scope["counts"].sum() == real_ct[0].size
