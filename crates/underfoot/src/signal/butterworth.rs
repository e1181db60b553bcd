//! TODO(helper): butterworth
