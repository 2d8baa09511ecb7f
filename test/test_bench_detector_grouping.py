"""bench/detector.py's choice of the drone-view node's grouping over training seeds (``node_grouping``): the rules
pick what they say on grids whose answers are known, and the held-out estimate of fold k never reads fold k's own
grid when it chooses."""
import importlib.util
from pathlib import Path

import pytest

_SPEC = importlib.util.spec_from_file_location("bench_detector", Path(__file__).resolve().parents[1] / "bench" / "detector.py")
bench = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(bench)

EAGER, CAREFUL, SPARSE = bench.grid_key(3, -0.5), bench.grid_key(5, -1.0), bench.grid_key(8, 0.0)


def grid(eager, careful, sparse=(0.80, 0.0)):
    """One fold's grid with three settings: ``[detection, false alarms]`` each."""
    return {EAGER: list(eager), CAREFUL: list(careful), SPARSE: list(sparse)}


def test_target_margin_is_the_nearer_side():
    assert bench.target_margin(0.95, 0.02) == pytest.approx(0.05)      # detection side nearer
    assert bench.target_margin(0.99, 0.07) == pytest.approx(0.03)      # false-alarm side nearer
    assert bench.target_margin(0.97, 0.12) == pytest.approx(-0.02)     # missed


def test_rules_differ_where_detection_and_false_alarms_trade():
    # the eager setting finds more everywhere at 7 % false alarms (inside the worst-fold rule's 8 %), the careful one
    # keeps 5 points from both sides of the target
    grids = [grid((0.99, 0.07), (0.95, 0.02)), grid((0.98, 0.06), (0.96, 0.01))]
    assert bench.choose_by_worst_fold(grids) == EAGER
    assert bench.choose_by_margin(grids) == CAREFUL
    # one fold past 8 % false alarms: the worst-fold rule turns careful too; the sparse setting misses too many
    grids.append(grid((0.97, 0.09), (0.94, 0.03)))
    assert bench.choose_by_worst_fold(grids) == CAREFUL
    assert bench.choose_by_margin(grids) == CAREFUL


def run(seed, fold_grids, inner_grids):
    folds = [{"grid": g, "inner_grids": {str(j): inner_grids[j] for j in range(len(fold_grids)) if j != k}}
             for k, g in enumerate(fold_grids)]
    return {"seed": seed, "folds": folds, "node_defaults": [3, -0.5]}


def test_held_out_choice_reads_only_the_other_folds(monkeypatch):
    monkeypatch.setattr(bench, "FOLDS", (("a",), ("b",)))
    # fold 0's own grid says careful (the eager setting fails it); fold 1's says eager. Choosing fold 0's setting
    # on fold 1's grid (inner) picks eager, and fold 0 is scored there: the held-out estimate shows its failure.
    own = [grid((0.97, 0.15), (0.95, 0.04)), grid((0.99, 0.01), (0.93, 0.00))]
    inner = own
    runs = {f"{bench.SHIPPED_RECIPE}_seed{s}": run(s, own, inner) for s in (0, 1)}
    runs["speed_640x480"] = {}                       # other entries of the results are passed over
    choice = bench.node_grouping(runs)
    margin = choice["rules"]["margin"]
    assert choice["seeds"] == [0, 1]
    assert margin["all_folds"]["setting"] == CAREFUL          # over both folds: 0.03 against -0.05
    held = {(h["seed"], h["fold"]): h for h in margin["held_out"]["folds"]}
    assert held[0, 0]["setting"] == EAGER and held[0, 0]["rates"] == [0.97, 0.15]
    assert held[1, 1]["setting"] == CAREFUL and held[1, 1]["rates"] == [0.93, 0.00]
    assert margin["held_out"]["folds_meeting_target"] == 2 and margin["held_out"]["cells"] == 4
    assert margin["held_out"]["worst_false_alarm_rate"] == pytest.approx(0.15)
    shown = choice["shown"]["node defaults of sessions 6-48"]
    assert shown["setting"] == EAGER and shown["folds_meeting_target"] == 2


def test_runs_without_grids_give_no_choice():
    assert bench.node_grouping({f"{bench.SHIPPED_RECIPE}_seed0": {"seed": 0, "folds": [{"regressed": {}}]}}) is None


def test_worst_fold_ties_go_to_the_later_setting_as_in_choose_grouping():
    # equal worst detection and false alarms: choose_grouping and choose_regressed keep the later setting of the grid
    # (more neighbours, a higher margin); the rule on stored grids must not pick otherwise
    grids = [grid((0.95, 0.05), (0.95, 0.05), (0.95, 0.05)), grid((0.97, 0.02), (0.96, 0.03), (0.97, 0.01))]
    assert bench.choose_by_worst_fold(grids) == SPARSE
    assert bench.worst_fold_key(0.95, 0.05) > bench.worst_fold_key(0.99, 0.09)   # over 8 %: after every one within
