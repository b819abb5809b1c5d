//! motu-gen
