//! The table of users.
