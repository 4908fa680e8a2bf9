"""studies/element_tests.py: runs, writes its pictures and CSV, and agrees with the closed forms."""

import csv
import importlib.util
import math
import pathlib

import pytest

STUDY = pathlib.Path(__file__).resolve().parents[1] / "studies" / "element_tests.py"


def load_study():
    spec = importlib.util.spec_from_file_location("element_tests_study", STUDY)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_element_test_study_writes_outputs_matching_closed_forms(tmp_path, capsys):
    study = load_study()
    out = tmp_path / "element_tests"
    assert study.main(["--out", str(out), "--n-steps", "40", "--c", "100", "--psi", "10"]) == 0
    for name in study.OUTPUTS:
        assert (out / name).stat().st_size > 0, name
    assert (out / "meridional.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with open(out / "failure_deviators.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert {r["path"] for r in rows} == {"triaxial_compression", "triaxial_extension"}
    assert len(rows) == 2 * len(study.DEFAULTS["confinements"])
    s = math.sin(math.radians(study.DEFAULTS["phi"]))
    for r in rows:
        assert r["failed"] == "True"
        sign = -1.0 if r["path"] == "triaxial_compression" else 1.0
        q_cf = 6 * s * (float(r["p_f_Pa"]) + 100.0 / math.tan(math.radians(30.0))) / (3 + sign * s)
        assert float(r["q_f_Pa"]) == pytest.approx(q_cf, rel=1e-10)
        assert float(r["q_closed_form_Pa"]) == pytest.approx(q_cf, rel=1e-12)
        assert float(r["rel_error"]) < 1e-10
    assert "largest relative error" in capsys.readouterr().out
    with pytest.raises(SystemExit):  # refuses to overwrite a non-empty directory
        study.main(["--out", str(out)])


def test_element_test_study_setup_is_importable_and_validated():
    study = load_study()
    data = study.setup(confinements=(1e5,), n_steps=20, c=50.0)
    assert data["material"].c == 50.0 and len(data["results"]) == 4
    assert all(row["rel_error"] < 1e-10 for row in data["failure"])
    with pytest.raises(TypeError):
        study.setup(friction=30.0)
