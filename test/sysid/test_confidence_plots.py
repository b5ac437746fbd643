"""Band plots: Bode, step and simulated output are written and say their sigma."""

from maglev_ros.sysid import arx

from .systems import simulate_siso


def test_band_plots_are_written(tmp_path):
    from maglev_ros.sysid.confidence_plots import (
        bode_band_plot,
        output_band_figure,
        step_band_figure,
    )
    from maglev_ros.sysid.plots import _save

    data = simulate_siso(1000, seed=3)
    models = [arx(data, 2, 2, 1), arx(data, 3, 3, 1)]
    assert bode_band_plot(models, tmp_path / 'bode.png', ['ARX 2 2 1', 'ARX 3 3 1']).stat().st_size
    fig = step_band_figure(models, 50, ['a', 'b'], sigma=2)
    assert '2-standard-deviation' in fig.texts[0].get_text()
    assert _save(output_band_figure(models[0], data), tmp_path / 'out.png').exists()
