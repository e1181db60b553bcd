//! TODO(helper): built-in library
