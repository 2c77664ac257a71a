"""The fixed-rate live loop on a servo link: clock, real-time scheduling, safety, scenarios, recording."""
