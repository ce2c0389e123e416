"""Shared fixtures: the S3 server (SeaweedFS on loopback, one per test worker)."""

pytest_plugins = ["tests.s3server"]
