//! motu-gpu
