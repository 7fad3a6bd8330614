//! save helpers
