//! A user as an argument (`calibrate sweep --load`, `run --user`): a limb file, Table 1's
//! mean user, or three parameters.

use std::path::PathBuf;

use underfoot::compensation::files::LimbFile;
use underfoot::compensation::limb::{DEFAULT_G2, LimbModel, LimbParams};
use underfoot::document;
use underfoot::io::spec::SpecError;
use underfoot::units::Band;

/// A user: a limb file, Table 1's mean (`table1`), or three parameters.
#[derive(Debug, Clone)]
pub enum UserArg {
    Params(LimbParams),
    File(PathBuf),
}

/// `table1`, `B3K3,K2M2,B2M2` (three numbers, validated) or a limb file.
///
/// # Errors
/// Three numbers that are not a valid limb.
pub fn parse_user(s: &str) -> Result<UserArg, SpecError> {
    if s == "table1" {
        return Ok(UserArg::Params(LimbParams::TABLE1_MEAN));
    }
    let parts: Vec<&str> = s.split(',').collect();
    if parts.len() == 3 {
        let values: Result<Vec<f64>, _> = parts.iter().map(|p| p.trim().parse::<f64>()).collect();
        if let Ok(v) = values {
            let params = LimbParams::from_array([v[0], v[1], v[2]]);
            params.validate().map_err(|e| SpecError::Invalid {
                what: "user",
                input: s.to_owned(),
                reason: e.to_string(),
            })?;
            return Ok(UserArg::Params(params));
        }
    }
    Ok(UserArg::File(PathBuf::from(s)))
}

impl UserArg {
    /// The limb model, and who it is for messages.
    pub fn model(&self) -> anyhow::Result<(LimbModel, String)> {
        match self {
            UserArg::Params(p) => Ok((
                LimbModel::new(*p, DEFAULT_G2, 1.0)?,
                format!(
                    "a user with b3/k3 = {}, k2/m2 = {}, b2/m2 = {}",
                    p.b3_k3, p.k2_m2, p.b2_m2
                ),
            )),
            UserArg::File(path) => {
                let file: LimbFile = document::load(path)?;
                Ok((file.model, path.display().to_string()))
            }
        }
    }

    /// The band its compensation covers: the file's, or the default sweep band.
    pub fn band(&self) -> anyhow::Result<Band> {
        match self {
            UserArg::Params(_) => Ok(Band::new(40.0, 1024.0)),
            UserArg::File(path) => Ok(document::load::<LimbFile>(path)?.band),
        }
    }
}
