//! motu-abi
