

def test_the_display_shows_latency_backlog_residual_verdict_and_key_angles():
    import io

    from exubio.live.display import Display
    from exubio.live.loop import Event

    out = io.StringIO()
    d = Display(out)
    d.status({"frame": 10, "time_s": 0.1, "latency_ms_p50": 1.5, "latency_ms_max": 3.0, "frames_behind": 2,
              "residual_mean_mm": 4.2, "verdict": "check", "reason": "", "angles_deg": {"HT_X_elevation": -40.0,
              "GH_X_elevation": -30.0, "ST_X_upward_rotation": -10.0, "GH_Y_internal_rotation": 5.0},
              "dropped": 1, "late": 0, "skipped": 0, "tracking": True, "gaps": ["EPI_lat"]})
    d.event(Event("gap", 10, 0.1, "marker EPI_lat missing: its spring is off", ("EPI_lat",)))
    text = out.getvalue()
    for part in ("latency 1.50 ms", "behind   2", "residual   4.2 mm", "CHECK", "HT elev", "-40.0", "dropped 1",
                 "gaps: EPI_lat", "gap: marker EPI_lat missing"):
        assert part in text, part
    quiet = io.StringIO()
    q = Display(quiet, quiet=True)
    q.event(Event("gap", 10, 0.1, "x"))
    q.event(Event("verdict", 10, 0.1, "fail: y"))
    assert "gap" not in quiet.getvalue() and "verdict: fail: y" in quiet.getvalue()
