"""The flight engine's sans-IO parts: typed events and the bus they travel on."""
