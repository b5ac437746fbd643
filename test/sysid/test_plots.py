from maglev_ros.sysid import armax, arx, bode_plot, compare_plot, resid, resid_plot

from .systems import C_ARMAX, simulate_mimo_arx, simulate_siso

PNG = b'\x89PNG'


def test_plots_write_png(tmp_path):
    est, val = simulate_siso(2000, 1, C=C_ARMAX).split(0.5)
    models = [arx(est, 2, 2, 1), armax(est, 2, 2, 1, 1)]
    p1 = compare_plot(val, models, tmp_path / 'cmp.png', ['arx', 'armax'])
    p2 = resid_plot(resid(models[0], val), tmp_path / 'sub' / 'resid.png')
    p3 = bode_plot(models, tmp_path / 'bode.png')
    for p in (p1, p2, p3):
        assert p.read_bytes()[:4] == PNG and p.stat().st_size > 5000


def test_mimo_plots(tmp_path):
    est, val = simulate_mimo_arx(1500, 1).split(0.5)
    model = arx(est, [[4, 4], [0, 4]], [[2, 2], [0, 2]], 1)
    assert compare_plot(val, [model], tmp_path / 'c.png', horizon=5).exists()
    assert bode_plot([model], tmp_path / 'b.png').exists()
    assert resid_plot(resid(model, val), tmp_path / 'r.png').exists()
