"""maglev_ros.hardware."""
