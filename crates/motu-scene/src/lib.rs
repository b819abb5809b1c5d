//! motu-scene
