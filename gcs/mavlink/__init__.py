"""MAVLink to the vehicles: links and transports, signing, the mission and command
protocols, telemetry and the vehicle facade."""
