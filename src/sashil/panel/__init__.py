"""sashil panel: the loopback server of the bench page (the app, its guard, the bench run, the run folders it serves)."""
