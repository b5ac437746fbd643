"""maglev_ros.cli."""
