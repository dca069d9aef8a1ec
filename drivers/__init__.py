"""Device drivers: the only code that touches hardware or OS devices."""
