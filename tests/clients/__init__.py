"""Tests of the client SDKs against the live service."""
