//! motu-trace
