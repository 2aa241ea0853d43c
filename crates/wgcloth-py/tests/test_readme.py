"""The README's Python example runs as written (both READMEs hold the same)."""

import re

from conftest import ROOT


def python_blocks(path):
    return re.findall(r"```python\n(.*?)```", path.read_text(), re.S)


def test_the_readme_example_runs(capsys, monkeypatch, tmp_path):
    [example] = python_blocks(ROOT / "README.md")
    assert python_blocks(ROOT / "crates" / "wgcloth-py" / "README.md") == [example]
    monkeypatch.chdir(tmp_path)
    exec(compile(example, "README.md", "exec"), {})
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].split()[0] in ("gpu", "cpu")
    assert [l.split()[0] for l in lines[1:]] == ["0", "1", "2", "3"]
