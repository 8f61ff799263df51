"""One confidence scale: a model's scores mapped onto the general model's, fitted from boxes judged right or wrong."""

from __future__ import annotations

import numpy as np
import pytest

from bevflow.detect.confidence import ScoreMap, fit_platt, fit_score_map

SCORES = np.array([0.0, 0.05, 0.3, 0.5, 0.56, 0.9, 0.999, 1.0])


def _logit(p: np.ndarray) -> np.ndarray:
    return np.log(p / (1 - p))


def _judged(rng: np.random.Generator, a: float, b: float, n: int = 20000) -> tuple[np.ndarray, np.ndarray]:
    """Scores spread over (0, 1) and judgements drawn with P(right) = σ(a · logit(score) + b)."""
    scores = rng.uniform(0.02, 0.98, n)
    right = rng.random(n) < 1 / (1 + np.exp(-(a * _logit(scores) + b)))
    return scores, right


@pytest.mark.parametrize("score_map", [ScoreMap(), ScoreMap(0.57, -0.51), ScoreMap(2.0, 1.0), ScoreMap(1.0, -3.0)])
def test_a_map_keeps_the_order_and_the_ends_and_its_inverse_finds_the_raw_score(score_map: ScoreMap) -> None:
    mapped = score_map(SCORES)
    assert np.all(np.diff(mapped) > 0)  # monotone: each model alone ranks its boxes as before
    assert (mapped[0], mapped[-1]) == (0.0, 1.0)
    for raw in SCORES:
        assert score_map.raw(float(score_map(raw))) == pytest.approx(raw, abs=1e-9)


def test_the_identity_changes_nothing() -> None:
    assert np.array_equal(ScoreMap()(SCORES), SCORES)
    assert ScoreMap().raw(0.56) == 0.56


@pytest.mark.parametrize(("text", "expected"), [("0.568162 -0.507443", ScoreMap(0.568162, -0.507443)), (" 1  0 ", ScoreMap())])
def test_a_map_is_kept_as_text(text: str, expected: ScoreMap) -> None:
    assert ScoreMap.from_text(text) == expected
    assert ScoreMap.from_text(expected.to_text()) == expected


@pytest.mark.parametrize(("text", "message"), [("0.5", "two numbers"), ("a b", "two numbers"), ("1 2 3", "two numbers"),
                                               ("-1 0", "slope > 0"), ("0 0", "slope > 0"), ("nan 0", "slope > 0"),
                                               ("1 inf", "finite offset")])
def test_a_bad_map_is_refused_saying_why(text: str, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        ScoreMap.from_text(text)


@pytest.mark.parametrize(("a", "b"), [(1.0, 0.0), (2.0, -1.5), (3.6, 0.3), (0.5, 1.0)])
def test_platt_scaling_recovers_the_chance_of_being_right(a: float, b: float) -> None:
    fitted = fit_platt(*_judged(np.random.default_rng(1), a, b))
    assert fitted == pytest.approx((a, b), abs=0.12)


def test_a_mapped_score_has_the_reference_score_s_chance_of_being_right() -> None:
    rng = np.random.default_rng(2)
    model, reference = (2.0, -1.5), (3.6, 0.3)
    score_map = fit_score_map(_judged(rng, *model), _judged(rng, *reference))
    raw = np.array([0.3, 0.56, 0.8])
    chance_model = 1 / (1 + np.exp(-(model[0] * _logit(raw) + model[1])))
    mapped = score_map(raw)
    chance_reference = 1 / (1 + np.exp(-(reference[0] * _logit(mapped) + reference[1])))
    assert chance_reference == pytest.approx(chance_model, abs=0.02)
    assert score_map.slope == pytest.approx(2.0 / 3.6, abs=0.05)


@pytest.mark.parametrize(("scores", "right", "message"), [
    ([0.2, 0.8], [True, True], "right and boxes judged wrong"),
    ([0.2, 0.8], [False, False], "right and boxes judged wrong"),
    ([0.2, 0.8, 0.5], [True, False], "3 scores but 2 judgements"),
])
def test_a_fit_without_both_kinds_of_box_is_refused(scores: list[float], right: list[bool], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        fit_platt(scores, right)


def test_scores_that_say_nothing_about_being_right_fit_no_map() -> None:
    rng = np.random.default_rng(3)
    noise = (rng.uniform(0.02, 0.98, 5000), rng.random(5000) < 0.5)
    with pytest.raises(ValueError, match="say little about being right"):
        fit_score_map(noise, _judged(rng, 3.6, 0.3))


def test_boxes_split_cleanly_by_score_are_too_few_to_fit_and_say_so() -> None:
    rng = np.random.default_rng(4)
    scores = rng.uniform(0.05, 0.95, 400)
    clean = (scores, scores > 0.5)  # every box above 0.5 right, every one below wrong: the slope runs away
    with pytest.raises(ValueError, match="too cleanly to fit .* give more frames"):
        fit_score_map(clean, _judged(rng, 3.6, 0.3))
