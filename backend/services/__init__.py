"""Business rules, independent of HTTP: each function takes an open connection and the caller."""
