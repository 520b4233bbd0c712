"""Examples of learning with mwip_ros.envs (numpy only)."""
