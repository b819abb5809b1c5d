//! motu-package
