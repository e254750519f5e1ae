"""The SDS Arduino: its line protocol (and, with issue 8, the serial bridge node)."""
