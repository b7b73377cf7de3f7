//! Errors and arguments: bitrock's errors as the package's exceptions, naming the keyword
//! argument the caller wrote, and keyword arguments read and checked by name.

use bitrock::Law;
use bitrock::error::Error;
use pyo3::exceptions::PyKeyboardInterrupt;
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// Keyword arguments whose names differ from the library's configuration fields: an error
/// about the field names the argument the caller wrote.
pub(crate) const ARGUMENTS: &[(&str, &str)] = &[
    ("speed_column", "speed_col"),
    ("torque_column", "torque_col"),
    ("wob_column", "wob_col"),
    ("time_column", "time_col"),
    ("top_drive_column", "top_drive_col"),
    ("surface_torque_column", "surface_torque_col"),
    ("downhole_min_column", "downhole_min_col"),
    ("downhole_max_column", "downhole_max_col"),
    ("rop_column", "rop_col"),
    ("axial_speed_column", "axial_speed_col"),
    ("axial_acceleration_column", "axial_acceleration_col"),
    ("noise_sd", "noise_sd_knm"),
    ("prior", "prior_file"),
    ("bounded", "bounds"),
    ("no_bounds", "bounds=False"),
];

/// `message` with the configuration fields it names (`` `speed_column` ``) said as the
/// keyword arguments a Python caller writes (`` `speed_col` ``).
pub(crate) fn as_arguments(message: &str) -> String {
    ARGUMENTS.iter().fold(message.to_string(), |text, (field, argument)| {
        text.replace(&format!("`{field}`"), &format!("`{argument}`"))
    })
}

/// Pickling by JSON, exact to the bit (shortest round-trip decimals): `state` as text, and
/// `object`'s type to rebuild it with its `_from_state` ([`from_json_state`]).
pub(crate) fn reduce_to_json<'py>(
    object: &Bound<'py, PyAny>,
    state: &impl serde::Serialize,
    what: &str,
) -> PyResult<(Bound<'py, PyAny>, (String,))> {
    let text = serde_json::to_string(state).map_err(|e| {
        to_py(
            object.py(),
            Error::Numerical(format!("the {what} cannot be pickled: {e}")),
        )
    })?;
    Ok((object.get_type().getattr("_from_state")?, (text,)))
}

/// What a pickle's JSON `state` ([`reduce_to_json`]) describes; one that does not read is an
/// `InputError` naming `argument`.
pub(crate) fn from_json_state<T: serde::de::DeserializeOwned>(
    py: Python<'_>,
    state: &str,
    argument: &str,
    what: &str,
) -> PyResult<T> {
    serde_json::from_str(state).map_err(|e| {
        to_py(
            py,
            Error::setting(argument, format!("the pickled {what} cannot be read: {e}")),
        )
    })
}

/// The Python exception for a library error: `InputError` naming the argument, the matching
/// `OSError` for files, `GpuError`, `KeyboardInterrupt` for a run stopped by Ctrl-C,
/// `BitrockError` otherwise (all but the last two defined in Python, so that they pickle).
pub(crate) fn to_py(py: Python<'_>, err: Error) -> PyErr {
    let message = as_arguments(&err.to_string());
    if matches!(err, Error::Interrupted) {
        return PyKeyboardInterrupt::new_err(message);
    }
    let built = py.import("bitrock._errors").and_then(|errors| match &err {
        Error::InvalidSetting { field, message } => {
            let argument = ARGUMENTS
                .iter()
                .find(|(f, _)| f == field)
                .map_or(field.as_str(), |(_, a)| a);
            errors
                .getattr("InputError")?
                .call1((format!("{argument}: {}", as_arguments(message)), argument))
        }
        Error::Read { path, source } | Error::Write { path, source } | Error::Output { path, source, .. } => errors
            .getattr("os_error")?
            .call1((source.raw_os_error().unwrap_or(0), message, path.display().to_string())),
        Error::Gpu(_) => errors.getattr("GpuError")?.call1((message,)),
        e if e.is_bad_input() => errors.getattr("InputError")?.call1((message, py.None())),
        _ => errors.getattr("BitrockError")?.call1((message,)),
    });
    match built {
        Ok(value) => PyErr::from_value(value),
        Err(e) => e,
    }
}

/// `Ok` or the Python exception of the library's error.
pub(crate) fn check<T>(py: Python<'_>, result: bitrock::Result<T>) -> PyResult<T> {
    result.map_err(|e| to_py(py, e))
}

/// A value of one of the library's lowercase enums (`cpu`, `smc`, `nested`…) from its name.
pub(crate) fn named<T: serde::de::DeserializeOwned>(
    py: Python<'_>,
    argument: &str,
    value: Option<String>,
) -> PyResult<Option<T>> {
    value
        .map(|v| {
            serde_json::from_value(serde_json::Value::String(v.to_lowercase())).map_err(|_| {
                to_py(
                    py,
                    Error::setting(argument, format!("`{v}` is not one of the accepted values")),
                )
            })
        })
        .transpose()
}

/// A unit from its command-line name (`rpm`, `rad_s`, `knm`, `nm`, `kn`, `n`), read as a
/// column suffix is.
pub(crate) fn unit<T>(
    py: Python<'_>,
    argument: &str,
    value: Option<String>,
    from_suffix: fn(&str) -> Option<T>,
) -> PyResult<Option<T>> {
    value
        .map(|v| {
            from_suffix(&format!("column_{}", v.to_lowercase()))
                .ok_or_else(|| to_py(py, Error::setting(argument, format!("unknown unit `{v}`"))))
        })
        .transpose()
}

/// The laws named in `laws`, or `None` for every law; refused as the command refuses its
/// `--laws` (an unknown law, one listed twice, none).
pub(crate) fn laws(py: Python<'_>, laws: Option<Vec<String>>) -> PyResult<Option<Vec<Law>>> {
    laws.map(|names| {
        if let Some(name) = names.iter().find(|n| n.contains(',')) {
            return Err(to_py(
                py,
                Error::setting("laws", format!("`{name}` is not one law's name")),
            ));
        }
        bitrock::laws::parse_law_list(&names.join(",")).map_err(|e| to_py(py, Error::setting("laws", e)))
    })
    .transpose()
}

/// The keyword argument `key` of `kw`, `None` when absent or `None`. A value of the wrong
/// type or out of range (a negative count, an integer beyond 64 bits, a string for a number)
/// and a bool where a number belongs (`particles=True`) are `InputError`s naming `key`.
pub(crate) fn kwarg<'py, T>(kw: &Bound<'py, PyDict>, key: &str) -> PyResult<Option<T>>
where
    T: for<'a> FromPyObject<'a, 'py> + 'static,
    for<'a> <T as FromPyObject<'a, 'py>>::Error: Into<PyErr>,
{
    let Some(value) = kw.get_item(key)?.filter(|v| !v.is_none()) else {
        return Ok(None);
    };
    let py = kw.py();
    let refuse = |why: String| {
        let shown = value.repr().map_or_else(|_| "the value".to_string(), |r| r.to_string());
        to_py(py, Error::setting(key, format!("{shown} is not accepted: {why}")))
    };
    if value.is_instance_of::<pyo3::types::PyBool>() && std::any::TypeId::of::<T>() != std::any::TypeId::of::<bool>() {
        return Err(refuse("a bool is not a number here".into()));
    }
    value
        .extract()
        .map(Some)
        .map_err(|e| refuse(Into::<PyErr>::into(e).value(py).to_string()))
}

/// A kind of run's settings `S` from the keyword arguments of `kw` that are its fields (the
/// library's gate, [`bitrock::run::settings`]); `None` values take the defaults. A value its
/// field cannot take is an `InputError` naming the field and showing the value, as [`kwarg`]'s
/// are; a name of one of the library's enums is read in any case, as [`named`] reads it.
pub(crate) fn settings<S>(kw: &Bound<'_, PyDict>) -> PyResult<S>
where
    S: serde::Serialize + serde::de::DeserializeOwned + Default,
{
    use bitrock::run::settings::{fields, from_named};
    let py = kw.py();
    let dumps = py.import("json")?.getattr("dumps")?;
    let mut named = serde_json::Map::new();
    for field in fields::<S>() {
        let Some(value) = kw.get_item(&field)?.filter(|v| !v.is_none()) else {
            continue;
        };
        let shown = value.repr().map_or_else(|_| "the value".to_string(), |r| r.to_string());
        let refuse = |why: String| to_py(py, Error::setting(&field, format!("{shown} is not accepted: {why}")));
        let text: String = dumps
            .call1((&value,))
            .and_then(|t| t.extract())
            .map_err(|_| refuse("not a number, string, or list of them".into()))?;
        let json: serde_json::Value = serde_json::from_str(&text).map_err(|_| refuse("not a finite number".into()))?;
        let alone = |json: serde_json::Value| from_named::<S>(serde_json::Map::from_iter([(field.clone(), json)]));
        let json = match alone(json.clone()) {
            Ok(_) => json,
            Err(error) => match json.as_str().map(str::to_lowercase).map(serde_json::Value::String) {
                Some(lower) if alone(lower.clone()).is_ok() => lower,
                Some(_) if error.to_string().contains("unknown variant") => {
                    let v = value.extract::<String>()?;
                    return Err(to_py(
                        py,
                        Error::setting(&field, format!("`{v}` is not one of the accepted values")),
                    ));
                }
                _ => {
                    let why = match error {
                        Error::InvalidSetting { message, .. } => message,
                        other => other.to_string(),
                    };
                    return Err(refuse(why));
                }
            },
        };
        named.insert(field, json);
    }
    check(py, from_named(named))
}

/// The fields of a kind of run's settings (`abc`, `evidence`, `coupled`, `surface`): the keyword arguments its Python
/// function must take, as the command takes their flags.
#[pyfunction]
pub(crate) fn settings_fields(py: Python<'_>, kind: &str) -> PyResult<Vec<String>> {
    match kind {
        "abc" => Ok(bitrock::run::settings::fields::<bitrock::run::abc::Settings>()),
        "evidence" => Ok(bitrock::run::settings::fields::<bitrock::run::evidence::Settings>()),
        "coupled" => Ok(bitrock::run::settings::fields::<bitrock::run::coupled::Settings>()),
        "surface" => Ok(bitrock::run::settings::fields::<bitrock::run::surface::Settings>()),
        other => Err(to_py(
            py,
            Error::setting(
                "kind",
                format!("no kind of run `{other}`; the kinds are abc, evidence, coupled, surface"),
            ),
        )),
    }
}
