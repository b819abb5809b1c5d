//! pbrt-import
