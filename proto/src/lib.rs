//! wire contract
