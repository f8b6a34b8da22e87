"""partcal._yamlio: YAML with line numbers."""

from conftest import ROOT

from partcal._yamlio import load_yaml


def test_numbers_in_exponent_notation_are_numbers(tmp_path):
    path = tmp_path / "a.yaml"
    path.write_text("a: 1e-3\nb: -2E5\nc: 1.5e2\nd: +3e0\nrows: 1-1000\nname: 1e\njoint: q1\nn: 12\n")
    data, lines = load_yaml(path)
    assert data == {"a": 0.001, "b": -200000.0, "c": 150.0, "d": 3.0, "rows": "1-1000", "name": "1e",
                    "joint": "q1", "n": 12}
    assert lines["b"] == 2


def test_a_run_config_reads_a_coverage_written_95e_2(tmp_path):
    from partcal.study.config import load_config

    path = tmp_path / "run.yaml"
    path.write_text(f"name: s\ndata:\n  identification: {ROOT / 'data' / 'sk120' / 'identification.csv'}\n"
                    "spread: {coverage: 95e-2}\nmodels:\n  - {name: a, degree: 1, solver: {method: lstsq}}\n")
    assert load_config(path).spread.coverage == 0.95
