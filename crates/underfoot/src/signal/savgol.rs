//! TODO(helper): savgol
