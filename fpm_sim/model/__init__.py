"""MuJoCo model generation: options, links (segments, cable, flex), the manipulator, the rigs, MJCF export."""
