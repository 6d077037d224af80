from __future__ import annotations

from types import SimpleNamespace

import pytest

from unitrack_env.evaluation.scorecard.eta import (
    CellClock,
    cell_cost,
    longest_first,
    schedule,
)


def test_cost_grows_with_frames_and_input_size_and_torch():
    assert cell_cost("vos", 100, appearance=True) > cell_cost("vos", 10, appearance=True)
    assert cell_cost("mot", 50, appearance=True) > cell_cost("pose-prop", 50, appearance=True)
    assert cell_cost("mot", 50, appearance=True, torch_runtime=True) > \
        cell_cost("mot", 50, appearance=True)
    assert cell_cost("mot", 50, appearance=False) < cell_cost("mot", 50, appearance=True)


def test_longest_first_keeps_the_plan_order_on_ties():
    assert longest_first([1.0, 5.0, 1.0, 3.0]) == [1, 3, 0, 2]


def test_the_eta_is_known_before_any_cell_and_corrected_by_measured_speed():
    clock = CellClock([10.0, 10.0, 10.0, 10.0], ["a"] * 4, workers=2, now=0.0)
    assert clock.remaining(now=0.0) == pytest.approx(20.0)
    assert clock.remaining(now=4.0) == pytest.approx(16.0)  # counts down while cells run
    clock.finished(0, 20.0, now=20.0)  # twice as slow as estimated
    # cells now take 20 s: cell 1 is due, cell 2 just started, cell 3 follows cell 1
    assert clock.remaining(now=20.0) == pytest.approx(20.0)  # 10 s without the correction
    clock.finished(1, 20.0, now=20.0)
    assert clock.remaining(now=30.0) == pytest.approx(10.0)


def test_groups_learn_their_own_speed_and_others_borrow_the_mean():
    clock = CellClock([10.0, 10.0, 10.0], ["a", "b", "b"], workers=1, now=0.0)
    clock.finished(0, 5.0, now=5.0)  # group a runs at half the estimate
    assert clock.remaining(now=5.0) == pytest.approx(10.0)  # b borrows a's rate
    clock.finished(1, 30.0, now=35.0)
    assert clock.remaining(now=35.0) == pytest.approx(30.0)


def test_schedule_orders_cells_longest_first():
    cells = [SimpleNamespace(task="pose-prop", head="UniTrack", model="m", frames=10),
             SimpleNamespace(task="vos", head="UniTrack", model="m", frames=50),
             SimpleNamespace(task="vos", head="repeat-mask", model="base", frames=50)]
    ordered, clock = schedule(cells, "base", workers=2)
    assert [c.task for c in ordered] == ["vos", "pose-prop", "vos"]
    assert clock.remaining(now=None) > 0


def test_a_group_borrows_its_own_models_speed_before_the_others():
    # model "big" runs at 3x its estimate, model "small" at its estimate
    clock = CellClock([10.0, 10.0, 10.0], [("big", "sot"), ("small", "sot"), ("big", "vos")],
                      workers=1, now=0.0)
    clock.finished(0, 30.0, now=30.0)
    clock.finished(1, 10.0, now=40.0)
    assert clock.remaining(now=40.0) == pytest.approx(30.0)  # big's 3x, not the mean 2x


def test_a_heavier_backbone_costs_more_and_schedules_first():
    from unitrack_env.agents.appearance.weights import load_weights
    from unitrack_env.evaluation.scorecard.eta import megapixel_gflops

    flops = {}
    for name, arch in (("small", None), ("big", "resnet18")):
        loaded = load_weights("random", arch=arch or "efficientnet-lite0")
        flops[name] = megapixel_gflops(loaded.module, loaded.layers, ["sot", "vos"])
    assert flops["small"]["sot"] == pytest.approx(24.3, abs=0.1)  # GFLOP per megapixel
    assert flops["big"]["vos"] == pytest.approx(105.1, abs=0.2)
    cells = [SimpleNamespace(task="sot", head="XCorr", model=m, frames=100)
             for m in ("small", "big")]
    ordered, clock = schedule(cells, "base", workers=1, gflop_per_mp=flops)
    assert [c.model for c in ordered] == ["big", "small"]
    assert clock.costs[0] > 2 * clock.costs[1]


def test_the_bar_says_planning_until_the_first_estimate_then_counts_down():
    import time

    from unitrack_env.evaluation.cli.scorecard import _EtaColumn

    column = _EtaColumn()
    task = SimpleNamespace(fields={}, finished=False)
    assert column.render(task).plain == "planning"
    task.fields["eta"] = (time.monotonic(), 3725.0)
    assert column.render(task).plain == "1:02:05"
    task.finished = True
    assert column.render(task).plain == "-:--:--"
