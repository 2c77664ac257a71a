"""The per-frame spine: ZMP, contacts, support polygon and clamp, foot sensors, and `Pipeline.step`."""
