"""A newcomer's first hour, as CI: a fresh clone, a fresh venv, the README's commands verbatim, timed.

    python scripts/newcomer_check.py [--repo PATH] [--workdir DIR] [--keep] [--dry-run]

1. ``git clone`` of the repository (default: the one this script is in; its committed ``HEAD``, not the
   working tree) into a temporary folder with nothing beside it (no ``../shared``);
2. the README's set-up blocks, extracted from the clone's ``README.md`` at run time (the fenced ``bash`` blocks
   under "## Set-up"), each run verbatim with ``bash -e`` in the clone: the first makes the venv and runs the
   main job (``fpm-sim reproduce``), the second installs the test extras and runs the fast test set;
3. the README's Python API block (the fenced ``python`` block under "## Python API"), run verbatim with the
   clone's venv.

Prints the time each step took (printed, not asserted: the machine decides it) and exits non-zero when a step
fails. ``--dry-run`` prints the extracted blocks and runs nothing. Needs git, network access to PyPI (the
venv installs the pinned stack) and some minutes.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

SETUP_HEADING = "## Set-up"
API_HEADING = "## Python API"


def section(markdown: str, heading: str) -> str:
    """The text of the section whose heading line starts with ``heading`` (up to the next heading of its level
    or above)."""
    level = heading.split(" ", 1)[0]
    lines = markdown.splitlines()
    try:
        start = next(i for i, line in enumerate(lines) if line.startswith(heading))
    except StopIteration:
        raise SystemExit(f"error: README.md has no section {heading!r}; update scripts/newcomer_check.py") from None
    ends = (i for i in range(start + 1, len(lines)) if 0 < len(lines[i].split(" ", 1)[0]) <= len(level)
            and set(lines[i].split(" ", 1)[0]) == {"#"})
    return "\n".join(lines[start : next(ends, len(lines))])


def fenced_blocks(text: str, language: str) -> list[str]:
    """The fenced code blocks of ``language`` in ``text``, verbatim (without the fences)."""
    return [m.group(1) for m in re.finditer(rf"^```{language}[ \t]*\n(.*?)^```", text, re.MULTILINE | re.DOTALL)]


def readme_steps(readme: str) -> list[tuple[str, str, str]]:
    """``(name, interpreter, code)`` of the README's set-up bash blocks and its Python API block."""
    setup = fenced_blocks(section(readme, SETUP_HEADING), "bash")
    api = fenced_blocks(section(readme, API_HEADING), "python")
    if not setup or len(api) != 1:
        raise SystemExit(
            f"error: expected bash blocks under {SETUP_HEADING!r} and one python block under {API_HEADING!r} "
            f"in README.md, found {len(setup)} and {len(api)}"
        )
    steps = [(f"README set-up block {i + 1}", "bash", code) for i, code in enumerate(setup)]
    steps.append(("README Python API block", "python", api[0]))
    return steps


def run(name: str, interpreter: str, code: str, cwd: Path) -> tuple[float, int]:
    """Run ``code`` in ``cwd``; bash with ``-e``, python with the clone's venv. Returns seconds and exit code."""
    env = dict(os.environ)
    env.pop("VIRTUAL_ENV", None)  # the clone's own venv, not the caller's
    env["MPLBACKEND"] = "Agg"
    if interpreter == "bash":
        argv = ["bash", "-e", "-c", code]
    else:
        python = cwd / ".venv" / "bin" / "python"
        if not python.exists():
            print(f"{name}: no venv in the clone ({python}); the set-up blocks make it", flush=True)
            return 0.0, 1
        argv = [str(python), "-c", code]
    print(f"\n===== {name} =====\n{code.strip()}\n-----", flush=True)
    t0 = time.perf_counter()
    rc = subprocess.run(argv, cwd=cwd, env=env, check=False).returncode
    return time.perf_counter() - t0, rc


def main() -> int:
    here = Path(__file__).resolve().parent.parent
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repo", default=str(here), help="repository to clone (path or URL; default: this one)")
    ap.add_argument("--workdir", type=Path, default=None, help="parent folder of the clone (default: a temp folder)")
    ap.add_argument("--keep", action="store_true", help="keep the clone afterwards")
    ap.add_argument("--dry-run", action="store_true", help="print the README's blocks as extracted, run nothing")
    ap.add_argument(
        "--steps",
        default="",
        help="comma-separated step numbers to run (1 = the main job, 2 = the tests, 3 = the Python API block); "
        "default all",
    )
    args = ap.parse_args()
    if args.dry_run:
        readme = Path(args.repo, "README.md").read_text() if Path(args.repo).is_dir() else ""
        for name, interpreter, code in readme_steps(readme):
            print(f"===== {name} ({interpreter}) =====\n{code}")
        return 0
    parent = Path(tempfile.mkdtemp(prefix="fpm_newcomer_", dir=args.workdir))
    clone = parent / "fpm-sim"  # nothing beside it: no ../shared
    timings: list[tuple[str, float, int]] = []
    t0 = time.perf_counter()
    rc = subprocess.run(["git", "clone", "--quiet", args.repo, str(clone)], check=False).returncode
    timings.append(("git clone", time.perf_counter() - t0, rc))
    if rc == 0:
        chosen = {int(v) for v in args.steps.split(",") if v.strip()}
        for k, (name, interpreter, code) in enumerate(readme_steps((clone / "README.md").read_text()), 1):
            if chosen and k not in chosen:
                continue
            seconds, code_rc = run(name, interpreter, code, clone)
            timings.append((name, seconds, code_rc))
    print("\n===== newcomer check: time per step (measured here, not asserted) =====")
    for name, seconds, code_rc in timings:
        print(f"{name:<28} {seconds:8.1f} s   {'ok' if code_rc == 0 else f'FAILED (exit {code_rc})'}")
    print(f"clone: {clone}" + ("" if args.keep else " (removed)"))
    if not args.keep:
        import shutil

        shutil.rmtree(parent, ignore_errors=True)
    return 0 if all(r == 0 for _, _, r in timings) else 1


if __name__ == "__main__":
    sys.exit(main())
