"""maglev_ros.bags."""
