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


def _inside_right_edge(fig, ax):
    """Whether the axes' legend overlaps the axes (drawn first)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig).draw()
    return ax.get_legend().get_window_extent().x0 < ax.get_window_extent().x1


def test_compare_figure_content():
    from maglev_ros.sysid import compare_figure

    from .systems import lab_second_order

    est, val = lab_second_order(N=4000).detrend().split(0.5)
    models = [arx(est, 2, 2, 1), arx(est, 1, 1, 1), armax(est, 2, 2, 1, 1)]
    labels = ['ARX 2 2 1', 'ARX 1 1 1', 'ARMAX 2 2 1 1']
    fig = compare_figure(val, models, labels, ic='estimate', zoom=100)
    rows, (zoom, inputs, error) = fig.axes[:3], fig.axes[3:6]
    # one row per model over the whole record, measured under it, on one scale
    for row, label in zip(rows, labels, strict=True):
        assert row.get_ylabel() == 'Bx [mT]'  # fields in T are drawn in mT
        assert row.get_xlim()[0] == val.time[0] == 0.4  # the validation half's own time
        texts = [t.get_text() for t in row.get_legend().get_texts()]
        assert texts[0] == 'measured' and texts[1].startswith(f'{label}: fit ')
        assert len(row.get_lines()) == 2 and row.get_ylim() == rows[0].get_ylim()
    assert rows[0].get_legend().get_texts()[1].get_text().startswith('ARX 2 2 1: fit 99.')
    legend = [t.get_text() for t in zoom.get_legend().get_texts()]
    assert all(
        text.endswith(' %') and len(text.split(': ')[1]) == len('99.99 %') for text in legend[1:]
    )
    measured = zoom.get_lines()[0].get_xdata()
    assert len(measured) == 100 and np.allclose(np.diff(measured), val.Ts)  # single samples
    assert 'zoom: 100 samples (20 ms)' in zoom.get_title(loc='left')
    # the errors as spectra, one per model, their RMS with three digits each
    assert 'error spectrum: measured - model' in error.get_title(loc='left')
    assert error.get_xscale() == 'log' and error.get_xlabel() == 'frequency [Hz]'
    assert len(error.get_lines()) == 3
    rms = [t.get_text().split('rms ')[1] for t in error.get_legend().get_texts()]
    assert all(len(v.split()[0].replace('0.', '').lstrip('0')) == 3 for v in rms), rms
    steps = inputs.get_lines()[0]
    assert steps.get_drawstyle() == 'steps-post' and len(steps.get_xdata()) == 100
    # legends beside the curves, not over them; the title names the models
    assert not any(_inside_right_edge(fig, ax) for ax in fig.axes)
    title = fig.get_suptitle()
    assert title.startswith('compare (simulation): Bx <- Ix; models ARX 2 2 1, ARX 1 1 1')


def test_mimo_compare_has_a_title_with_orders_and_one_error_scale():
    from maglev_ros.sysid import compare_figure

    est, val = simulate_mimo_arx(1500, 1).split(0.5)
    model = arx(est, [[4, 4], [0, 4]], [[2, 2], [0, 2]], 1)
    fig = compare_figure(val, [model, arx(est, 2, 2, 1)], ['ARX', 'ARX 2 2 1'])
    title = fig.get_suptitle().replace('\n', ' ')
    assert 'y1, y2 <- u1, u2' in title and 'ARX (na=[4 4;0 4]  nb=[2 2;0 2]' in title
    errors = [ax for ax in fig.axes if 'error spectrum' in ax.get_title(loc='left')]
    assert len(errors) == 2 and errors[0].get_ylim() == errors[1].get_ylim()


def test_bode_skips_structural_zeros_and_resid_names_the_model():
    from maglev_ros.sysid import bode_figure, resid_figure

    est, val = simulate_mimo_arx(1500, 1).split(0.5)
    model = arx(est, [[4, 4], [0, 4]], [[2, 2], [0, 2]], 1)
    fig = bode_figure([model], ['ARX'])
    axes = np.array(fig.axes).reshape(4, 2)
    assert axes[2, 0].get_lines() == [] and 'no path' in axes[2, 0].texts[0].get_text()
    low = min(line.get_ydata().min() for ax in axes[[0, 2]].ravel() for line in ax.get_lines())
    assert low > -300  # no -6000 dB floor
    assert fig.get_suptitle().startswith('Bode plot of the identified models: ARX (na=[4 4;0 4]')
    fig = bode_figure([model, model], ['ARX', 'the same'])
    first, second = fig.axes[0].get_lines()  # on top of each other: told apart by the dashes
    assert first.get_linestyle() != second.get_linestyle()
    fig = resid_figure(resid(model, val), model_label='ARX 4 2 1')
    assert fig.get_suptitle().startswith('ARX 4 2 1: residuals on validation data')
    assert max(len(line) for line in fig.get_suptitle().splitlines()) <= fig.get_figwidth() * 11


def test_an_exact_fit_says_so_in_its_error_panel(recwarn):
    """Noise-free data a model describes exactly: measured - model is 0 everywhere, which
    log axes cannot draw; the panel says so and draws no empty log scale (no warning)."""
    from maglev_ros.sysid import compare_figure
    from maglev_ros.sysid.dataset import IdData

    u = np.random.default_rng(0).standard_normal((400, 1))
    data = IdData(y=2.0 * u, u=u, Ts=1e-3)
    model = arx(data, 0, 1, 0)
    fig = compare_figure(data, [model], ['ARX 0 1 0'])
    error = fig.axes[-1]
    assert any('an exact fit' in t.get_text() for t in error.texts)
    assert not [w for w in recwarn if 'log-scaled' in str(w.message)]
