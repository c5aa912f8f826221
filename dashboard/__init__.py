"""Live visualisation: rerun recordings and the viser browser dashboard."""
