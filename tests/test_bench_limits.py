"""``sjt-pin bench accuracy``'s target stream (``bench.limits.franka``) on a short run: one row
per arm and method, every limit kept, the held target reached and the arm at rest."""

from sjt_pin.bench import limits


def test_the_stream_runs_on_panda_and_another_arm_within_every_limit():
    rows = limits.franka(methods=("sjt",), seconds=1.0, arms={"xarm7": (10.0, 5000.0)})
    assert [(r.path.split(",")[0], r.method) for r in rows] == [("panda", "SJT"),
                                                                 ("xarm7", "SJT")]
    for r in rows:
        assert max(r.speed, r.acceleration, r.jerk) <= 1.01 and r.in_range
        assert r.final_error < 1e-3 and r.rest < 1e-6
    table = limits.franka_table(rows).splitlines()
    assert len(table) == 4 and table[2].startswith("| panda, targets jumping")
