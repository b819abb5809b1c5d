//! motu-alloc
