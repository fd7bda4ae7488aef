"""Hardware emulators used as test fixtures (no hardware here); written from the protocol specs."""
