//! TODO(helper): filtfilt
