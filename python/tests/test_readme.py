"""The README's Python example, run as written on three generated scans."""

import re
from pathlib import Path

import mtpcr

from conftest import three_views

README = Path(__file__).resolve().parents[2] / "README.md"


def test_readme_python_example_runs(tmp_path, monkeypatch, capsys):
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), re.S)
    assert blocks, "the README has a Python example"
    views = three_views(seed=2, points_per_view=8000)
    for i, cloud in enumerate(views.clouds, start=1):
        mtpcr.write_ply(tmp_path / f"scan{i}.ply", cloud)
    monkeypatch.chdir(tmp_path)
    exec(compile(blocks[0], str(README), "exec"), {})
    out = capsys.readouterr().out
    assert "[[" in out, "the example prints T12"
