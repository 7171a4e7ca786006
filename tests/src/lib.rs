//! Integration tests of mtpcr live in `tests/`.
