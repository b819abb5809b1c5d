//! motu-compile
