//! motu-ingest
