"""Speed and accuracy studies (never asserted in tests)."""
