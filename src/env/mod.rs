//! The batched environment.
