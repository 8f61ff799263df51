from __future__ import annotations

import json
from pathlib import Path

import pytest

from bevflow_services.cli import main
from bevflow_services.cli.evaluate import parse_frame_slice
from bevflow_services.runtime import UserError
from tests.bevflow.datasets.test_wildtrack import write_fake_wildtrack

HEADLINE = {"MODA", "MODP", "precision", "recall", "F1", "APE", "method", "frames"}


@pytest.fixture(scope="module")
def root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_fake_wildtrack(tmp_path_factory.mktemp("cli") / "wildtrack")


def test_single_method_writes_headline_keys_at_the_top(root: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "result.json"
    rc = main(["evaluate", "--dataset", "wildtrack", "--root", str(root), "--jitter", "0.02", "--drop", "0.1", "--json", str(out)])
    assert rc == 0
    result = json.loads(out.read_text())
    assert HEADLINE <= result.keys()
    assert result["method"] == "cylinder" and result["frames"] == 3
    assert result["noise"] == {"jitter": 0.02, "drop": 0.1, "false_positives": 0.0, "truncation": True}
    printed = capsys.readouterr().out
    assert "MODA" in printed and "CVLab2" in printed


def test_all_methods_write_one_object_each(root: Path, tmp_path: Path) -> None:
    out = tmp_path / "all.json"
    assert main(["evaluate", "--dataset", "wildtrack", "--root", str(root), "--method", "all", "--frames", "1:", "--json", str(out)]) == 0
    results = json.loads(out.read_text())
    assert [r["method"] for r in results] == ["cylinder", "bbox-center", "nearest-point"]
    assert all(HEADLINE <= r.keys() and r["frames"] == 2 for r in results)


def test_nothing_to_divide_by_is_written_as_null(root: Path, tmp_path: Path) -> None:
    out = tmp_path / "none.json"
    assert main(["evaluate", "--dataset", "wildtrack", "--root", str(root), "--drop", "1", "--json", str(out)]) == 0
    result = json.loads(out.read_text())  # strict JSON: no NaN
    assert result["APE"] is None and result["precision"] is None and result["recall"] == 0.0


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--frames", "5"], "--frames"),
        (["--frames", "a:b"], "--frames"),
        (["--frames", "::0"], "step"),
        (["--frames", "10:20"], "selects none"),
        (["--drop", "1.5"], "--drop"),
        (["--jitter", "-1"], "--jitter"),
        (["--seed", "-3"], "--seed"),
        (["--false-positives", "-2"], "--false-positives"),
        (["--fusion-distance", "0"], "--fusion-distance"),
    ],
)
def test_bad_options_exit_2_with_one_line(root: Path, capsys: pytest.CaptureFixture, extra: list[str], message: str) -> None:
    assert main(["evaluate", "--dataset", "wildtrack", "--root", str(root), *extra]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


@pytest.mark.parametrize("args", [["--root", "{missing}"], []])
def test_missing_or_absent_root_is_a_user_error(tmp_path: Path, capsys: pytest.CaptureFixture, args: list[str]) -> None:
    args = [a.format(missing=tmp_path / "nowhere") for a in args]
    assert main(["evaluate", "--dataset", "wildtrack", *args]) == 2
    err = capsys.readouterr().err
    assert ("nowhere" in err if args else "--root" in err) and err.count("\n") == 1


def test_dataset_and_suite_are_exclusive(root: Path) -> None:
    with pytest.raises(SystemExit) as exit_:
        main(["evaluate", "--dataset", "wildtrack", "--suite", "paper", "--root", str(root)])
    assert exit_.value.code == 2


@pytest.mark.parametrize(
    ("args", "message"),
    [(["--suite", "no-such-suite"], "unknown suite"), (["--suite", "paper", "--frames", "0:5"], "--dataset only")],
)
def test_suite_mistakes_are_user_errors(capsys: pytest.CaptureFixture, args: list[str], message: str) -> None:
    assert main(["evaluate", *args]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


def test_help_explains_the_frame_slice(capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit) as exit_:
        main(["evaluate", "--help"])
    assert exit_.value.code == 0
    text = capsys.readouterr().out
    assert "--false-positives" in text and "0:50 = the first 50" in text


@pytest.mark.parametrize(
    ("text", "expected"),
    [(":", slice(None)), ("0:50", slice(0, 50)), ("150:", slice(150, None)), ("::2", slice(None, None, 2)), ("-10:", slice(-10, None))],
)
def test_frame_slices_parse_like_python(text: str, expected: slice) -> None:
    assert parse_frame_slice(text) == expected


def test_frame_slice_rejects_a_single_number() -> None:
    with pytest.raises(UserError):
        parse_frame_slice("3")
