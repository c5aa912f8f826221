"""MAVLink XML definitions of the vtol-ftc dialect (package so the XML ships as package data)."""
