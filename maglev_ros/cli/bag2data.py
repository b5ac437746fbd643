r"""``maglev-bag2data``: turn a rosbag2 bag into estimation and validation data sets.

Reads channels of a bag (MCAP or sqlite3, recorded by ``maglev_ros``'s recorder
or ``ros2 bag record``), aligns them on one uniform time base, splits them and
writes ``.npz``, ``.csv`` or ``.mat`` files (the lab's ``DATA`` layout)::

    maglev-bag2data run/ --topics
    maglev-bag2data run/ --reindex      # rebuild a bag whose recorder was killed
    maglev-bag2data run/ --output 'maglev/sensor_0/field:magnetic_field.x' \
        --input 'ux=0.5*maglev/currents:effort[0]-0.5*maglev/currents:effort[1]' \
        --out data.mat

Channel specs, the time-base rule and the gap policy: the README, section "Bags".
Exit status: 0 on success, 2 on bad input (one line on stderr).
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path

from ..topics import current_channel, field_channel
from .usage import Parser, UsageError, check_output_file, positive_float, run_command

__all__ = ['add_channel_arguments', 'build_parser', 'dataset_from_args', 'main', 'split_point']

PROG = 'maglev-bag2data'


def split_point(text: str) -> float | int:
    """Argparse type: a split fraction in (0, 1) (``0.5``) or a sample count (``12500``).

    Parameters
    ----------
    text : str
        The command-line text.
    """
    try:
        value: float | int = float(text) if any(c in text for c in '.eE') else int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f'expected a fraction or a sample count, got {text!r}'
        ) from None
    if isinstance(value, float) and not 0.0 < value < 1.0:
        raise argparse.ArgumentTypeError(f'a split fraction must be in (0, 1), got {text!r}')
    if isinstance(value, int) and value < 1:
        raise argparse.ArgumentTypeError(f'a split sample count must be >= 1, got {text!r}')
    return value


def _tolerance(text: str) -> float:
    value = positive_float(text)
    if value >= 0.5:
        raise argparse.ArgumentTypeError(f'must be a fraction of Ts below 0.5, got {text!r}')
    return value


def add_channel_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the bag channel options (shared with ``maglev-sysid``).

    Parameters
    ----------
    parser : argparse.ArgumentParser
        Gets ``--output``, ``--input``, ``--allow-gaps`` and ``--tolerance``
        (``--ts`` is left to the caller).
    """
    parser.add_argument(
        '--output',
        action='append',
        default=[],
        metavar='SPEC',
        help=f"output channel [NAME=]TOPIC:FIELD, e.g. '{field_channel(0, 'x')}' (repeat "
        "for more; the first one's topic defines the time base)",
    )
    parser.add_argument(
        '--input',
        action='append',
        default=[],
        metavar='SPEC',
        help=f"input channel, e.g. '{current_channel(0)}' or "
        f"'ux=0.5*{current_channel(0)}-0.5*{current_channel(1)}'",
    )
    parser.add_argument(
        '--allow-gaps',
        action='store_true',
        help='a bag: fill gaps (outputs linearly, inputs by zero-order hold) instead of '
        'refusing it; a data file whose time vector has gaps: keep its longest gap-free '
        'piece (reported) instead of refusing it',
    )
    parser.add_argument(
        '--tolerance',
        type=_tolerance,
        default=0.05,
        metavar='FRACTION',
        help='exact stamp match tolerance as a fraction of Ts (default 0.05)',
    )


def dataset_from_args(bag: str, args: argparse.Namespace) -> object:
    """Read a bag with the options of :func:`add_channel_arguments` (and ``--ts``).

    Parameters
    ----------
    bag : str
        Bag directory.
    args : argparse.Namespace
        Parsed options.

    Returns
    -------
    maglev_ros.bags.BagDataset
        The data set and its report.
    """
    from maglev_ros.bags import read_bag

    if not args.output:
        raise UsageError(
            'choose at least one --output channel (TOPIC:FIELD); --topics lists what the bag has'
        )
    return read_bag(
        bag,
        args.output,
        args.input,
        Ts=getattr(args, 'ts', None),
        allow_gaps=args.allow_gaps,
        tolerance=args.tolerance,
    )


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of ``maglev-bag2data``."""
    p = Parser(
        prog=PROG,
        description='Turn a rosbag2 bag (MCAP or sqlite3) into '
        'estimation/validation data sets (.npz, .csv, .mat).',
    )
    p.add_argument('bag', help='bag directory (with metadata.yaml)')
    add_channel_arguments(p)
    p.add_argument(
        '--ts',
        type=positive_float,
        metavar='SECONDS',
        help='sample time (default: estimated from the first output stamps)',
    )
    p.add_argument(
        '--split',
        type=split_point,
        default=0.5,
        help='estimation part: fraction (default 0.5) or sample count',
    )
    p.add_argument(
        '--out',
        metavar='FILE',
        help='write FILE (.npz, .csv or .mat) with all '
        'samples, and FILE_est / FILE_val with the two parts',
    )
    p.add_argument('--json', action='store_true', help='print the summary as JSON')
    p.add_argument(
        '--topics', action='store_true', help="list the bag's topics and run metadata, then exit"
    )
    p.add_argument(
        '--reindex',
        action='store_true',
        help='rebuild an unfinished bag (no metadata.yaml: a recording killed with SIGKILL '
        'or by a power loss) from its .mcap or .db3 file, keeping every complete message; '
        'the original file stays beside it as .damaged; then exit',
    )
    p.add_argument(
        '--force',
        action='store_true',
        help='with --reindex: rebuild a bag that has metadata.yaml but whose storage file '
        'is truncated (its run metadata is kept)',
    )
    return p


def _topics(bag: str, as_json: bool) -> int:
    from maglev_ros.bags import BagReader

    with BagReader(bag) as reader:
        topics = reader.topics
        info = {
            'bag': bag,
            'storage': reader.storage,
            'messages': reader.message_count,
            'duration_s': (reader.end_ns - reader.start_ns) * 1e-9,
            'topics': [
                {'topic': t.name, 'type': t.msgtype, 'messages': t.count} for t in topics.values()
            ],
            'metadata': reader.metadata,
        }
    if as_json:
        print(json.dumps(info, indent=2))
        return 0
    print(
        f'bag       {bag} ({info["storage"]}), {info["messages"]} messages, '
        f'{info["duration_s"]:.6g} s'
    )
    for t in info['topics']:
        print(f'topic     {t["topic"]} ({t["type"]}): {t["messages"]} messages')
    for key, value in info['metadata'].items():
        print(f'metadata  {key}: {value}')
    return 0


def _run(args: argparse.Namespace) -> int:
    from maglev_ros.bags import format_summary, write_dataset
    from maglev_ros.bags.export import split_paths

    if args.reindex:
        from maglev_ros.bags import reindex

        print(reindex(args.bag, force=args.force).describe())
        return 0
    if args.force:
        raise UsageError('--force goes with --reindex: maglev-bag2data BAG --reindex --force')
    if args.topics:
        return _topics(args.bag, args.json)
    if args.out:
        check_output_file('--out', args.out, create_parents=False)
        for path in split_paths(args.out):  # an unknown suffix fails here too
            check_output_file('--out', path, create_parents=False)
    ds = dataset_from_args(args.bag, args)
    summary = ds.summary(args.split)
    if args.out:
        est, val = ds.split(args.split)
        est_path, val_path = split_paths(args.out)
        summary['files'] = [
            str(write_dataset(ds.data, args.out)),
            str(write_dataset(est, est_path)),
            str(write_dataset(val, val_path)),
        ]
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(format_summary(summary))
        for name in summary.get('files', []):
            print(f'wrote     {Path(name)}')
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``maglev-bag2data``; return the exit status (2 on bad input).

    Parameters
    ----------
    argv : sequence of str, optional
        Arguments (default ``sys.argv[1:]``).

    Returns
    -------
    int
        Exit status.
    """
    return run_command(PROG, build_parser(), _run, argv)


if __name__ == '__main__':
    sys.exit(main())
