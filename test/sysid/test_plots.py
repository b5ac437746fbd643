import numpy as np

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


def test_compare_figure_content():
    from maglev_ros.sysid import compare_figure

    from .systems import lab_second_order

    est, val = lab_second_order(N=4000).detrend().split(0.5)
    models = [arx(est, 2, 2, 1), arx(est, 1, 1, 1)]
    fig = compare_figure(val, models, ['ARX 2 2 1', 'ARX 1 1 1'], ic='estimate', zoom=100)
    full, zoom, inputs, error = fig.axes[:4]
    assert full.get_ylabel() == 'Bx [mT]'  # fields in T are drawn in mT
    assert full.get_xlim()[0] == val.time[0] == 0.4  # the validation half's own time axis
    legend = [t.get_text() for t in full.get_legend().get_texts()]
    assert legend[0] == 'measured' and legend[1].startswith('ARX 2 2 1: 99.')
    assert all(
        text.endswith(' %') and len(text.split(': ')[1]) == len('99.99 %') for text in legend[1:]
    )
    measured = zoom.get_lines()[0].get_xdata()
    assert len(measured) == 100 and np.allclose(np.diff(measured), val.Ts)  # single samples
    assert 'zoom: 100 samples (20 ms)' in zoom.get_title(loc='left')
    assert error.get_title(loc='left').startswith('error: measured - model')
    assert 0.5 < np.abs(full.get_lines()[0].get_ydata()).max() < 10  # about 2 mT, not 2e-3
    assert len(error.get_lines()) == 3  # two models and the zero line
    steps = inputs.get_lines()[0]
    assert steps.get_drawstyle() == 'steps-post' and len(steps.get_xdata()) == 100


def test_bode_skips_structural_zeros_and_resid_names_the_model():
    from maglev_ros.sysid import bode_figure, resid_figure

    est, val = simulate_mimo_arx(1500, 1).split(0.5)
    model = arx(est, [[4, 4], [0, 4]], [[2, 2], [0, 2]], 1)
    fig = bode_figure([model], ['ARX'])
    axes = np.array(fig.axes).reshape(4, 2)
    assert axes[2, 0].get_lines() == [] and 'no path' in axes[2, 0].texts[0].get_text()
    low = min(line.get_ydata().min() for ax in axes[[0, 2]].ravel() for line in ax.get_lines())
    assert low > -300  # no -6000 dB floor
    fig = resid_figure(resid(model, val), model_label='ARX 4 2 1')
    assert fig.get_suptitle().startswith('ARX 4 2 1: residuals on validation data')
    assert max(len(line) for line in fig.get_suptitle().splitlines()) <= fig.get_figwidth() * 11
