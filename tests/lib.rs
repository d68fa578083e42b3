//! Shared helpers for the workspace test suite.
