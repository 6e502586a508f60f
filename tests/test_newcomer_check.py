"""scripts/newcomer_check.py finds the README's set-up and Python API blocks (it runs them verbatim in CI)."""

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _script():
    spec = importlib.util.spec_from_file_location("newcomer_check", ROOT / "scripts" / "newcomer_check.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_readme_blocks_are_found_verbatim():
    nc = _script()
    readme = (ROOT / "README.md").read_text()
    steps = nc.readme_steps(readme)
    bash = [code for _, interpreter, code in steps if interpreter == "bash"]
    (python,) = [code for _, interpreter, code in steps if interpreter == "python"]
    assert any("fpm-sim reproduce" in code for code in bash)  # the main job
    assert any("pytest" in code for code in bash)  # the fast test set
    assert "import fpm_sim" in python
    for code in [*bash, python]:
        assert code in readme  # verbatim, fences stripped
        assert "```" not in code


def test_a_section_ends_at_the_next_heading_of_its_level():
    nc = _script()
    text = "# T\n## Set-up here\n```bash\necho 1\n```\n### sub\n```bash\necho 2\n```\n## Next\n```bash\necho 3\n```\n"
    assert nc.fenced_blocks(nc.section(text, "## Set-up"), "bash") == ["echo 1\n", "echo 2\n"]
