"""maglev_ros.physics."""
