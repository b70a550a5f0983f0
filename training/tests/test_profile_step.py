"""The step profiler runs both stages on the CPU and reports a step time and the profiler's tables."""

from tensorholo_training import profile_step


def test_profile_step_times_both_stages_and_prints_the_profile(capsys, tmp_path):
    assert profile_step.main(["--device", "cpu", "--size", "16", "--steps", "2", "--repeats", "1",
                              "--rows", "80", "--run-dir", str(tmp_path / "run")]) == 0
    out = capsys.readouterr().out
    for stage in ("stage1", "stage2"):
        line = next(l for l in out.splitlines() if l.startswith(f"{stage}: 8 layers"))
        ms = float(line.rsplit(" ", 1)[1])
        assert ms > 0.0, line
        assert f"{stage}: 2 steps by cpu_time_total" in out
    # The profiler saw the network's convolutions.
    assert "aten::conv" in out
