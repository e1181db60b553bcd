//! TODO(lead): fitting a material model from recordings.
