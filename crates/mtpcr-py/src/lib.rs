//! Python bindings of mtpcr (placeholder crate until the bindings issue lands: it builds and
//! exposes nothing yet).
