//! TODO(lead): the measured response of a material.
