"""Every hook is documented in docs/hooks.md and exercised by a test (datasette's habit)."""

from pathlib import Path

from physinfer import hooks

ROOT = Path(__file__).resolve().parents[2]
HOOK_NAMES = sorted(n for n in dir(hooks) if n.startswith("physinfer_"))


def test_there_are_hooks():
    assert len(HOOK_NAMES) >= 5


def test_every_hook_documented():
    text = (ROOT / "docs" / "hooks.md").read_text()
    missing = [n for n in HOOK_NAMES if f"`{n}" not in text]
    assert not missing, f"undocumented hooks: {missing}"


def test_every_hook_tested():
    tests = "".join(p.read_text() for p in (ROOT / "tests").rglob("test_*.py") if p.name != Path(__file__).name)
    missing = [n for n in HOOK_NAMES if n not in tests]
    assert not missing, f"hooks no test uses: {missing}"
