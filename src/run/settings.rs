//! The gate a kind of run's settings pass: the kind has one serde `Settings` (a doc comment per
//! field, defaults in its `Default`; the ABC run's and the evidence's), which the command's
//! flags and Python's keyword arguments fill, and which turns into what the kind runs only after
//! it is validated, once. A setting therefore exists on every surface or on none: [`fields`]
//! lists a kind's, and the tests check that the command and Python take each.

use crate::error::{Error, Result};
use serde::Serialize;
use serde::de::DeserializeOwned;
use serde_json::{Map, Value};

/// The names of the fields of settings `S`, in alphabetical order.
pub fn fields<S: Serialize + Default>() -> Vec<String> {
    match serde_json::to_value(S::default()).expect("settings serialise") {
        Value::Object(map) => map.keys().cloned().collect(),
        _ => unreachable!("settings are a struct"),
    }
}

/// Settings `S` from named values (Python's keyword arguments as JSON), every other field at
/// its default. A name that is no field of `S`, and a value its field cannot take, are refused
/// naming the field.
pub fn from_named<S: Serialize + DeserializeOwned + Default>(named: Map<String, Value>) -> Result<S> {
    let known = fields::<S>();
    for (name, value) in &named {
        if !known.contains(name) {
            return Err(Error::setting(
                name,
                format!("is not a setting here; the settings are {}", known.join(", ")),
            ));
        }
        let alone = Map::from_iter([(name.clone(), value.clone())]);
        serde_json::from_value::<S>(Value::Object(alone)).map_err(|e| Error::setting(name, e.to_string()))?;
    }
    serde_json::from_value(Value::Object(named)).map_err(|e| Error::setting("settings", e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde::Deserialize;

    #[derive(Debug, Default, PartialEq, Serialize, Deserialize)]
    #[serde(default, deny_unknown_fields)]
    struct Example {
        particles: usize,
        share: f64,
    }

    #[test]
    fn named_values_fill_their_fields_and_refuse_by_name() {
        assert_eq!(fields::<Example>(), ["particles", "share"]); // alphabetical
        let named = Map::from_iter([("share".to_string(), Value::from(0.5))]);
        assert_eq!(
            from_named::<Example>(named).unwrap(),
            Example {
                particles: 0,
                share: 0.5
            }
        );
        let unknown = Map::from_iter([("particle".to_string(), Value::from(3))]);
        let e = from_named::<Example>(unknown).unwrap_err().to_string();
        assert!(e.contains("`particle`") && e.contains("particles, share"), "{e}");
        let wrong = Map::from_iter([
            ("share".to_string(), Value::from(0.5)),
            ("particles".to_string(), Value::from("many")),
        ]);
        let e = from_named::<Example>(wrong).unwrap_err().to_string();
        assert!(e.contains("`particles`") && e.contains("invalid type"), "{e}");
    }
}
