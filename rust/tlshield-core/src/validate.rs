//! Input checks shared by every layer: non-finite values reported with their position.

use crate::error::InputError;

/// Index of the first NaN or infinity. Scans blocks with a branch-free fold (vectorised) and
/// only searches inside a block that failed.
pub fn first_non_finite(data: &[f64]) -> Option<usize> {
    const BLOCK: usize = 64;
    data.chunks(BLOCK).enumerate().find_map(|(k, block)| {
        if block.iter().fold(true, |ok, v| ok & v.is_finite()) {
            None
        } else {
            block
                .iter()
                .position(|v| !v.is_finite())
                .map(|i| k * BLOCK + i)
        }
    })
}

/// Reports the first non-finite value of a row-major array as `name[row, col]`.
pub fn check_finite(name: &str, data: &[f64], dim: usize) -> Result<(), InputError> {
    match first_non_finite(data) {
        None => Ok(()),
        Some(i) if data.len() == dim => Err(InputError::NonFinite {
            what: format!("{name}[{i}]"),
            value: data[i],
        }),
        Some(i) => Err(InputError::NonFinite {
            what: format!("{name}[{}, {}]", i / dim, i % dim),
            value: data[i],
        }),
    }
}

/// Checks a restored step count against the horizon.
pub fn check_steps(t: u32, horizon: u32) -> Result<(), InputError> {
    if t > horizon {
        return Err(InputError::Value {
            what: "t".into(),
            expected: format!("a step count within the horizon (0..={horizon})"),
            got: t.to_string(),
        });
    }
    Ok(())
}
