"""MAVLink dialect and the links (UDP, zenoh) that carry MAVLink 2 frames."""
