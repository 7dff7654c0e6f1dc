"""The flight engine: the arrival controller, the learnt airspeed scale, the mission clock,
the team coordinator, and the typed events and bus it publishes on."""
