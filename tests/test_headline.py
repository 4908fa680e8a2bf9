"""The published numbers are written once: by the studies, into ``studies/REPORT.md``.

``studies/headline.py`` reads the claims out of the committed report into
``studies/headline.json`` and fills the README's validation table and ``docs/validation.md``'s
claims from it; ``studies/demo_picture.py`` fills the README's picture caption from the
picture's own text fields.  These tests fail when a generated file or region is not what its
generator makes from what is committed (a hand edit, or a report regenerated without
``python studies/headline.py``), and show that the generator reads the report's numbers
(change one in the report and the table changes) and names what it cannot find.
"""

import json
import pathlib
import re
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from study_files import load  # noqa: E402

headline = load("headline")
REPORT_TEXT = headline.REPORT.read_text(encoding="utf-8")


def test_committed_files_are_what_the_report_makes():
    files = headline.outputs(REPORT_TEXT)
    stale = [str(p.relative_to(ROOT)) for p in headline.stale(files)]
    assert not stale, f"not as generated from studies/REPORT.md: {stale}; run " \
                      f"'python studies/headline.py'"


def test_headline_json_names_its_report_and_each_studys_commit():
    data = json.loads(headline.HEADLINE.read_text(encoding="utf-8"))
    assert data["made_by"] == "python studies/headline.py"
    assert re.search(rf"\(git {re.escape(data['report_commit'])}\)", REPORT_TEXT)
    for claim in data["claims"]:
        assert claim["study_commit"] and claim["study_created"], claim["key"]
        assert f"## {claim['section']}\n" in REPORT_TEXT, claim["key"]


def test_the_flow_mode_map_count_is_read_from_the_report():
    """The map's agreement comes from its table's rows on the map's own cells: one row
    flipped, one fewer; a flipped grid-check row (on finer cells) counts in the grid check."""
    before = {c["key"]: c for c in headline.build(REPORT_TEXT)["claims"]}["flow_mode_cones"]
    assert "in-sample" in before["result"] and "not placed on" in before["result"]
    values = before["values"]
    agree, cases = values["agree"], values["cases"]
    def row(prefix):         # the map's row of a case (its numbers as the report has them)
        return next(line for line in REPORT_TEXT.splitlines()
                    if line.startswith(prefix) and line.endswith("| yes |"))

    own = row("| 10 | 10 | 5 | 44.8 | mass | mass |")
    check = row("| 40 | 10 | 2.5 | 44.8 | mass | mass |")
    assert own in REPORT_TEXT and check in REPORT_TEXT
    flipped = REPORT_TEXT.replace(own, own.replace("| mass | mass |", "| mass | funnel |")
                                  .replace("| yes |", "| no |"), 1)
    after = {c["key"]: c for c in headline.build(flipped)["claims"]}["flow_mode_cones"]
    assert after["values"] == {**values, "agree": agree - 1}
    assert after["result"].startswith(f"{agree - 1} of {cases} cases agree")
    table = headline.readme_table({**headline.build(flipped), "claims": [after]})
    assert f"| {agree - 1} of {cases} cases agree" in table
    flipped = REPORT_TEXT.replace(check, check.replace("| yes |", "| no |"), 1)
    after = {c["key"]: c for c in headline.build(flipped)["claims"]}["flow_mode_cones"]
    assert after["values"] == {**values,
                               "grid_check_agree": values["grid_check_agree"] - 1}


def test_a_hand_edit_of_the_readme_table_is_found(tmp_path):
    files = headline.outputs(REPORT_TEXT)
    readme = files[headline.README]
    body = headline._docs.region(readme, "headline")
    first = re.search(r"\| (\d+) of (\d+) cases agree", body)
    edited = readme.replace(first[0], f"| {int(first[1]) + 1} of {first[2]} cases agree", 1)
    (tmp_path / "README.md").write_text(edited, encoding="utf-8")
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "validation.md").write_text(files[headline.VALIDATION],
                                                     encoding="utf-8")
    (tmp_path / "studies").mkdir()
    (tmp_path / "studies" / "headline.json").write_text(files[headline.HEADLINE],
                                                        encoding="utf-8")
    made = headline.outputs(REPORT_TEXT, root=tmp_path)
    assert headline.stale(made) == [tmp_path / "README.md"]


def test_a_finding_the_claims_cannot_read_is_named():
    broken = REPORT_TEXT.replace("Mean |difference| from Beverloo x Rose-Tanaka",
                                 "Mean |difference| from Beverloo times Rose-Tanaka")
    with pytest.raises(headline.HeadlineError, match="study 'discharge_rate': no finding"):
        headline.build(broken)


def test_a_missing_region_writes_nothing(tmp_path):
    (tmp_path / "README.md").write_text("# no regions\n", encoding="utf-8")
    with pytest.raises(headline._docs.RegionError, match="README.md.*headline"):
        headline.outputs(REPORT_TEXT, root=tmp_path)


def test_every_claim_names_tests_that_exist():
    for claim in headline.CLAIMS:
        assert claim.tests, claim.key
        for nodeid in claim.tests:
            kind, text = headline.test_statement(nodeid)
            assert text, nodeid
    with pytest.raises(headline.HeadlineError, match="does not exist"):
        headline.test_statement("tests/test_validation.py::test_no_such_test")


def test_readme_picture_caption_is_the_pictures_own_record():
    picture = load("demo_picture")
    fields = picture.fields_of()
    assert re.fullmatch(r"[0-9a-f]{7,}", fields["fipy_hopper:commit"]), fields
    assert "demo" in fields["fipy_hopper:command"]
    assert picture.readme_text() == picture.README.read_text(encoding="utf-8"), \
        "README.md's picture caption is not the picture's: run 'python studies/demo_picture.py'"
    assert picture.PICTURE.stat().st_size < 400_000


def test_the_picture_is_stale_once_a_later_commit_changes_what_it_draws(tmp_path):
    """``demo_picture.py --check``'s rule on a constructed repository: a picture made at a
    commit is up to date while the later commits touch other files, stale (one line naming
    the commit and the file) once one changes the plotting or the wall loads, and stale when
    it records no commit or one the checkout does not hold."""
    import subprocess

    from PIL import Image, PngImagePlugin

    picture = load("demo_picture")

    def git(*args):
        out = subprocess.run(["git", "-C", str(tmp_path), "-c", "user.name=t",
                              "-c", "user.email=t@example.org", *args],
                             capture_output=True, text=True, check=True)
        return out.stdout.strip()

    def commit(path, text):
        (tmp_path / path).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / path).write_text(text, encoding="utf-8")
        git("add", path)
        git("commit", "-q", "-m", f"change {path}")
        return git("rev-parse", "--short", "HEAD")

    def draw(recorded):
        info = PngImagePlugin.PngInfo()
        info.add_text("fipy_hopper:commit", recorded)
        png = tmp_path / "docs" / "images" / "demo.png"
        png.parent.mkdir(parents=True, exist_ok=True)
        Image.new("RGB", (4, 4), "white").save(png, pnginfo=info)
        return png

    git("init", "-q")
    made = commit("fipy_hopper/plotting.py", "a = 1\n")
    png = draw(made)
    assert picture.stale_reason(tmp_path, png) is None
    commit("fipy_hopper/io.py", "b = 1\n")
    assert picture.stale_reason(tmp_path, png) is None
    later = commit("fipy_hopper/wall_traction.py", "c = 1\n")
    reason = picture.stale_reason(tmp_path, png)
    assert reason and "\n" not in reason
    assert f"git {made}" in reason and f"git {later}" in reason
    assert "fipy_hopper/wall_traction.py" in reason and "demo_picture.py hopper_run" in reason
    assert picture.stale_reason(tmp_path, draw(git("rev-parse", "--short", "HEAD"))) is None
    assert "records no commit" in picture.stale_reason(tmp_path, draw("not recorded"))
    assert "does not hold" in picture.stale_reason(tmp_path, draw("0123abc"))
