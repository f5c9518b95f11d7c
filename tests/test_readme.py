"""The README's first lines are the newcomer's two commands; CI runs the test one verbatim."""

from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _commands():
    lines = (ROOT / "README.md").read_text().splitlines()[:5]
    return [ln.split("`")[1] for ln in lines if ln.count("`") >= 2]


def test_readme_starts_with_run_and_test_commands():
    run, test = _commands()[:2]
    assert "pip install ." in run and "groundstation" in run
    assert 'pip install ".[test]"' in test and "pytest" in test


def test_ci_runs_the_readme_test_command_exactly():
    test = _commands()[1]
    ci_lines = (ROOT / ".ci" / "run").read_text().splitlines()
    assert test in ci_lines


def test_flying_guide_documents_every_telemetry_field_and_parameter():
    from onboard.link import telemetry as tm
    from onboard.link.params import PARAM_SPECS

    text = (ROOT / "docs" / "flying.md").read_text(encoding="utf-8")
    for i, (name, _, _) in enumerate(tm.FIELDS):
        assert f"| {i} | `{name}` |" in text, name
    for spec in PARAM_SPECS:
        assert f"| `{spec.param_id}` | `{spec.name}` | {spec.default:g} |" in text, spec.name
