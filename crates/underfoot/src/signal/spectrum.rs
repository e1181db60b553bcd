//! TODO(helper): spectrum
