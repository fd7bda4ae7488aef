"""Real-time Cosserat-rod statics for cable/tendon-driven continuum robots."""
