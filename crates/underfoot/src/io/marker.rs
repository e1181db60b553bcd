//! Markers: moments of a session an experimenter names (a trial's start, an answer, an
//! incident), from a page, an HTTP call, OSC (`/underfoot/v2/marker`) or a terminal, for a
//! session's record ([`crate::live::record`]).

use serde::{Deserialize, Serialize};

/// The longest marker text, in bytes.
pub const MAX_MARKER_TEXT: usize = 1000;
/// The longest participant or condition, in bytes.
pub const MAX_MARKER_FIELD: usize = 200;

/// A marker: a moment of the session an experimenter names (a trial's start, an
/// answer, an incident), with the trial it belongs to when there is one.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Marker {
    /// What happened, free text (at most [`MAX_MARKER_TEXT`] bytes).
    pub text: String,
    /// The trial number.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trial: Option<u32>,
    /// The participant's code.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub participant: Option<String>,
    /// The condition.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub condition: Option<String>,
}

impl Marker {
    /// A marker of `text` alone.
    #[must_use]
    pub fn new(text: impl Into<String>) -> Self {
        Self {
            text: text.into(),
            ..Self::default()
        }
    }

    /// Whether it can be recorded: text not empty, no field too long or holding a
    /// control character (a line break would split a log's line).
    ///
    /// # Errors
    /// [`MarkerError`] saying which field and why.
    pub fn check(&self) -> Result<(), MarkerError> {
        let bad = |reason: String| Err(MarkerError(reason));
        if self.text.trim().is_empty() {
            return bad("a marker needs a text".into());
        }
        if self.text.len() > MAX_MARKER_TEXT {
            return bad(format!(
                "the text is {} bytes, at most {MAX_MARKER_TEXT}",
                self.text.len()
            ));
        }
        for (name, value) in [
            ("text", Some(&self.text)),
            ("participant", self.participant.as_ref()),
            ("condition", self.condition.as_ref()),
        ] {
            let Some(value) = value else { continue };
            if name != "text" && value.len() > MAX_MARKER_FIELD {
                return bad(format!(
                    "the {name} is {} bytes, at most {MAX_MARKER_FIELD}",
                    value.len()
                ));
            }
            if value.chars().any(char::is_control) {
                return bad(format!("the {name} holds a control character"));
            }
        }
        Ok(())
    }
}

/// Why a marker cannot be recorded.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("marker refused: {0}")]
pub struct MarkerError(pub String);
