"""maglev_ros: ROS 2 tools for the Maggy magnetic-levitation lab."""

__version__ = '0.1.0'
