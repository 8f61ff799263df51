from __future__ import annotations

import json
from pathlib import Path

import pytest

from bevflow.evaluation.replay import HEADLINE
from bevflow_services.cli import main
from tests.bevflow.evaluation.test_replay import replay, write_recording
from tests.bevflow.evaluation.test_wildtrack_tracking import walkers


@pytest.fixture
def recording(tmp_path: Path) -> Path:
    write_recording(walkers(0.7), tmp_path)
    return tmp_path


def args(folder: Path, *extra: str) -> list[str]:
    return ["evaluate", "--detections", str(folder / "detections"), "--site", str(folder / "site.json"),
            "--truth", str(folder / "truth.txt"), "--fps", "2", *extra]


def test_replay_prints_and_writes_the_scores_and_the_tracks(recording: Path, capsys: pytest.CaptureFixture) -> None:
    out, tracks = recording / "scores.json", recording / "tracks.txt"
    assert main(args(recording, "--json", str(out), "--tracks-out", str(tracks))) == 0
    result = json.loads(out.read_text())
    expected = replay(recording, min_confidence=0.5)
    assert {k: result[k] for k in HEADLINE} == pytest.approx(expected.headline())
    assert result["frames"] == 8 and result["min_confidence"] == 0.5
    rows = [line.split(",") for line in tracks.read_text().splitlines()]
    assert len(rows) == sum(len(t) for _, t in expected.tracks) > 0
    assert {int(r[0]) for r in rows} <= set(range(8)) and all(len(r) == 4 for r in rows)
    printed = capsys.readouterr().out
    assert "HOTA" in printed and "settled" in printed and "confidence >= 0.5" in printed
    identities = result["identities"]
    assert identities["person_frames"] == expected.scores.n_gt == sum(p["frames"] for p in identities["people"])
    assert identities["main"] + identities["unmatched"] <= identities["person_frames"]
    assert identities["unmatched"] <= expected.scores.fn  # the most pairs within 0.5 m: no more misses than CLEAR-MOT
    assert f"identities: of {identities['person_frames']} person-frames, " in printed


def test_perturbed_copies_print_and_write_the_spread_of_each_score(recording: Path, capsys: pytest.CaptureFixture) -> None:
    out = recording / "scores.json"
    assert main(args(recording, "--perturb", "2", "--perturb-drop", "0.6", "--perturb-jitter", "1", "--json", str(out))) == 0
    result = json.loads(out.read_text())
    spread = result["perturbed"]
    assert (spread["runs"], spread["drop"], spread["jitter_px"]) == (2, 0.6, 1.0)
    assert set(HEADLINE) - {"frames"} <= spread.keys()
    recall = spread["recall"]
    assert recall["min"] <= recall["mean"] <= recall["max"] < result["recall"]  # most boxes gone
    printed = capsys.readouterr().out
    assert "2 perturbed copies (each box dropped with probability 0.6, each edge moved 1 px" in printed
    assert all(line in printed for line in ("\nmean ", "\nmin ", "\nmax "))
    # none asked for: no copies replayed, no key written
    assert main(args(recording, "--json", str(out))) == 0
    assert "perturbed" not in json.loads(out.read_text()) and "perturbed copies" not in capsys.readouterr().out


def test_ideal_runs_track_the_truth_alone_and_write_their_spread(recording: Path, capsys: pytest.CaptureFixture) -> None:
    out = recording / "scores.json"
    assert main(args(recording, "--ideal-noise", "0.05", "--perturb", "2", "--json", str(out))) == 0
    result = json.loads(out.read_text())
    ideal = result["ideal"]
    assert (ideal["noise_m"], ideal["runs"]) == (0.05, 2)
    assert set(HEADLINE) - {"frames"} <= ideal.keys()
    assert ideal["precision"]["min"] == 1.0  # the truth alone: nobody else to find
    printed = capsys.readouterr().out
    assert "the truth moved by 0.05 m (σ), tracked alone, 2 seed(s):" in printed
    # none asked for: no key written
    assert main(args(recording, "--json", str(out))) == 0
    assert "ideal" not in json.loads(out.read_text()) and "tracked alone" not in capsys.readouterr().out


def test_hypotheses_override_the_sites_and_are_named(recording: Path, capsys: pytest.CaptureFixture) -> None:
    out = recording / "scores.json"
    assert main(args(recording, "--hypotheses", "5", "--json", str(out))) == 0
    assert json.loads(out.read_text())["tracker"]["hypotheses"] == 5
    printed = capsys.readouterr().out
    assert "5 hypotheses over 2 s" in printed and "settled: as decided 2 s later, then one update late" in printed
    assert main(args(recording, "--json", str(out))) == 0  # the site's own: the default, 20
    assert json.loads(out.read_text())["tracker"]["hypotheses"] == 20 and "20 hypotheses" in capsys.readouterr().out
    assert main(args(recording, "--hypotheses", "1", "--json", str(out))) == 0  # each update decided at once
    assert json.loads(out.read_text())["tracker"]["hypotheses"] == 1 and "hypotheses" not in capsys.readouterr().out


@pytest.mark.parametrize(
    ("option", "views"),
    [
        pytest.param(None, True, id="the site's default: WILDTRACK's side cameras take views"),
        pytest.param("--fuse-first", False, id="fused first"),
        pytest.param("--track-views", True, id="views"),
    ],
)
def test_the_tracks_take_the_views_or_the_fused_people_and_say_which(
    recording: Path, capsys: pytest.CaptureFixture, option: str | None, views: bool
) -> None:
    out = recording / "scores.json"
    assert main(args(recording, *([option] if option else []), "--json", str(out))) == 0
    tracker = json.loads(out.read_text())["tracker"]
    assert (tracker["track_views"], tracker["report_max_misses"]) == (views, 0 if views else 1)
    said = "each camera's views matched to the tracks" if views else "views fused before tracking"
    printed = capsys.readouterr().out
    assert said in printed
    assert ("every camera looks from the side" in printed) is (option is None)  # why, where the site chose


def test_track_views_and_fuse_first_together_are_refused(recording: Path, capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit):
        main(args(recording, "--track-views", "--fuse-first"))
    assert "not allowed with argument" in capsys.readouterr().err


def test_the_area_leaves_out_unmatched_tracks_beyond_it(recording: Path, tmp_path: Path) -> None:
    # the walkers stand at y = -2, 0, 2 m: an area around the first one scores only them
    out = tmp_path / "area.json"
    assert main(args(recording, "--area=-5,-3,10,-1", "--json", str(out))) == 0
    result = json.loads(out.read_text())
    assert result["tracked"]["n_gt"] == 3 * 8 and result["tracked"]["fp"] == 0


@pytest.mark.parametrize(
    ("change", "extra", "message"),
    [
        (None, ("--fps", "0"), "--fps must be a number of frames per second > 0"),
        (None, ("--area", "1,2,3"), "--area must be four numbers"),
        (None, ("--area", "3,0,1,2"), "--area needs XMAX > XMIN"),
        (None, ("--min-confidence", "-1"), "--min-confidence must be a number >= 0"),
        (None, ("--perturb", "-1"), "--perturb must be a number of copies >= 0"),
        (None, ("--perturb", "2", "--perturb-drop", "1"), "--perturb-drop, --perturb-jitter: drop must be a probability in [0, 1)"),
        (None, ("--perturb", "2", "--perturb-jitter", "nan"), "--perturb-drop, --perturb-jitter: jitter_px must be a number of pixels >= 0"),
        (None, ("--ideal-noise", "-0.1"), "--ideal-noise must be a number of metres >= 0"),
        (None, ("--hypotheses", "0"), "--hypotheses must be a whole number from 1 to 100, got 0"),
        (None, ("--hypotheses", "101"), "--hypotheses must be a whole number from 1 to 100, got 101"),
        ("missing camera", (), "CVLab2.txt: no detections file for camera 'CVLab2'"),
        ("bad row", (), "CVLab1.txt:3: 'wide' is not a number"),
        ("bad truth", (), "truth.txt:1: expected at least 4"),
        ("far truth frame", (), "and frame 100000000 (the truth): a replay steps through every frame"),
    ],
)
def test_bad_input_is_one_clear_message(recording: Path, capsys: pytest.CaptureFixture, change, extra, message) -> None:
    if change == "missing camera":
        (recording / "detections" / "CVLab2.txt").unlink()
    elif change == "bad row":
        path = recording / "detections" / "CVLab1.txt"
        lines = path.read_text().splitlines()
        lines[2] = "2,-1,10,10,wide,30,0.9"
        path.write_text("\n".join(lines))
    elif change == "bad truth":
        (recording / "truth.txt").write_text("0,1,2\n")
    elif change == "far truth frame":  # 100000 typed as 100000000: years of empty frames to step
        with (recording / "truth.txt").open("a") as f:
            f.write("\n100000000,1,2.0,2.0\n")
    assert main(args(recording, *extra)) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_replay_needs_site_truth_and_fps(recording: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["evaluate", "--detections", str(recording / "detections"), "--fps", "2"]) == 2
    assert "--detections needs --site" in capsys.readouterr().err
