//! TODO(lead): IIR fitting.
