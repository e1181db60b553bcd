pub mod calibrate;
pub mod compare;
pub mod demo;
pub mod fit;
pub mod library;
pub mod render;
pub mod run;
pub mod synth;
