from depth.bench import bench_adapter


def test_bench_adapter_reports_both_throughputs():
    result = bench_adapter(size=32, n_frames=4, batch_size=2, repeats=1)
    assert result["size"] == 32 and result["n_frames"] == 4
    assert result["adapter_fps"] > 0 and result["session_fps"] > 0
    assert result["adapter_over_session"] > 0
