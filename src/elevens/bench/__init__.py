"""What `elevens bench ...` runs. Speed is measured here, never in unit tests."""
