"""maglev_ros.sysid."""
