"""ROS-free rosbag2 tools: record bags, read them, turn them into identification data.

Writing (:class:`BagWriter`), reading (:class:`BagReader`), channel specs
(:func:`parse_channel`), the time-base rule (:func:`align`) and bag -> data set
(:func:`read_bag`, :func:`load_bag_dataset`, :func:`write_dataset`).  Uses
rosbags only; rclpy is never imported here.
"""

from .alignment import Alignment, Gap, Source, SourceReport, align, estimate_period
from .channels import Channel, FieldRef, parse_channel, parse_field_path
from .datasets import BagDataset, load_bag_dataset, read_bag
from .errors import BagError
from .export import format_summary, write_dataset
from .reader import METADATA_TOPIC, BagReader, TopicInfo, is_bag_directory, is_bag_path
from .reindex import ReindexReport, reindex
from .writer import BagWriter, TopicHandle

__all__ = [
    'METADATA_TOPIC',
    'Alignment',
    'BagDataset',
    'BagError',
    'BagReader',
    'BagWriter',
    'Channel',
    'FieldRef',
    'Gap',
    'ReindexReport',
    'Source',
    'SourceReport',
    'TopicHandle',
    'TopicInfo',
    'align',
    'estimate_period',
    'format_summary',
    'is_bag_directory',
    'is_bag_path',
    'load_bag_dataset',
    'parse_channel',
    'parse_field_path',
    'read_bag',
    'reindex',
    'write_dataset',
]
