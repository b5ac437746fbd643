import io

import pytest

from maglev_ros.cli import progress


class Terminal(io.StringIO):
    def isatty(self):
        return True


@pytest.mark.parametrize(
    ('stream', 'quiet', 'shown'),
    [(Terminal, False, True), (Terminal, True, False), (io.StringIO, False, False)],
)
def test_bars_only_on_a_terminal_without_quiet(monkeypatch, stream, quiet, shown):
    err = stream()
    monkeypatch.setattr(progress.sys, 'stderr', err)
    with progress.progress_bar(4, 'simulating', 'samples', quiet) as bar:
        bar.update(4)
    with progress.stage('finding the equilibrium', quiet):
        pass
    text = err.getvalue()
    assert ('simulating:   0%|' in text and 'finding the equilibrium...' in text) == shown
    assert (text == '') == (not shown)


def test_model_simulate_is_quiet_when_not_a_terminal(capfd):
    from maglev_ros.cli.model import main

    assert main(['simulate', '--duration', '0.002']) == 0
    out, err = capfd.readouterr()
    assert err == '' and 'status: ok' in out
