"""maglev_ros.nodes."""
