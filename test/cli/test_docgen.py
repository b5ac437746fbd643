"""The generated parameters page: complete, and the committed one up to date."""

from pathlib import Path

import pytest

from maglev_ros.cli import docgen

PAGE = Path(__file__).resolve().parents[2] / 'docs' / 'reference' / 'parameters.md'


def test_every_node_table_is_found():
    nodes = {node.executable: node for node in docgen.node_parameter_tables()}
    assert {'simulator', 'driver', 'estimator', 'controller', 'recorder'} <= set(nodes)
    assert nodes['simulator'].table.node_name == 'maglev_simulator'


def test_the_page_lists_every_parameter_of_every_node():
    nodes = docgen.node_parameter_tables()
    page = docgen.parameter_page(nodes)
    for node in nodes:
        section = page.split(f'## `{node.executable}`\n', 1)[1].split('\n## ', 1)[0]
        for name in node.table:
            assert f'| `{name}` |' in section, f'{node.executable}: {name} missing'


def test_the_committed_page_is_up_to_date(capsys):
    status = docgen.main(['--check', '--out', str(PAGE)])
    assert status == 0, capsys.readouterr().err


def test_a_stale_page_is_reported(tmp_path, capsys):
    stale = tmp_path / 'parameters.md'
    stale.write_text(PAGE.read_text().replace('| `params` |', '| `parameter_set` |', 1))
    assert docgen.main(['--check', '--out', str(stale)]) == 1
    assert 'is stale: run python -m maglev_ros.cli.docgen' in capsys.readouterr().err


def test_writes_the_page(tmp_path):
    out = tmp_path / 'parameters.md'
    assert docgen.main(['--out', str(out)]) == 0
    assert out.read_text() == PAGE.read_text()


@pytest.mark.parametrize('argv', [['--out', 'no/such/dir/p.md'], ['--check', '--out', 'none.md']])
def test_bad_paths_are_one_line_and_status_2(tmp_path, monkeypatch, capsys, argv):
    monkeypatch.chdir(tmp_path)
    assert docgen.main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert err[0].startswith('python -m maglev_ros.cli.docgen: error: ')
