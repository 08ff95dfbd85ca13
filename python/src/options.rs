//! An integrator's options from `render`'s keywords: `light_paths=1000` stands for
//! `--light-paths 1000`, read by the parser of the command line
//! ([`registry::parse_options`]), so that values, defaults and errors are the command
//! line's and a keyword the integrator does not read is an error naming those that do.

use pcbpt::integrator::registry;
use pcbpt::integrator::{IntegratorKind, Method};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict};

/// `kind`'s options from keywords (`name=value`, the command line's `--name` with `-` for
/// `_`). A value is passed as `str(value)`; a boolean as `true`/`false` to an option that
/// takes a value (clap's `ArgAction::Set`, as every boolean option is declared), and to a
/// flag as the flag itself or nothing; None leaves the
/// option at its default.
pub fn method(kind: IntegratorKind, options: &Bound<'_, PyDict>) -> PyResult<Method> {
    let command = registry::options_command(kind);
    let mut args = Vec::new();
    for (key, value) in options.iter() {
        let key: String = key.extract()?;
        let long = key.replace('_', "-");
        let Some(arg) = command.get_arguments().find(|a| names(a).any(|n| n == long)) else {
            let why = registry::not_an_option_of(&format!("--{long}"), kind);
            return Err(PyValueError::new_err(format!("{key}: {why}")));
        };
        args.extend(arguments(&long, arg, &value)?);
    }
    registry::parse_options(kind, &args).map_err(PyValueError::new_err)
}

/// The long name and aliases of `arg`.
fn names(arg: &clap::Arg) -> impl Iterator<Item = &str> {
    arg.get_long().into_iter().chain(arg.get_all_aliases().unwrap_or_default())
}

/// The command-line arguments that give option `--long` (`arg`) the value `value`.
fn arguments(long: &str, arg: &clap::Arg, value: &Bound<'_, PyAny>) -> PyResult<Vec<String>> {
    let flag = format!("--{long}");
    if value.is_none() {
        return Ok(Vec::new());
    }
    if let Ok(b) = value.cast::<PyBool>() {
        let b = b.is_true();
        return Ok(match arg.get_action() {
            // A flag: given for the value it sets, left out for the other.
            clap::ArgAction::SetTrue if b => vec![flag],
            clap::ArgAction::SetFalse if !b => vec![flag],
            clap::ArgAction::SetTrue | clap::ArgAction::SetFalse => Vec::new(),
            _ => vec![format!("{flag}={b}")],
        });
    }
    // One argument, `--name=value`, so that a value starting with `-` is not taken for a flag.
    Ok(vec![format!("{flag}={}", value.str()?)])
}
