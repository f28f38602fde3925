//! Settings files (the style and fit presets): a JSON object of some of the
//! settings' keys merged over a base, so a missing key keeps the base's value
//! and a key the settings do not have (a typo) is refused with its path.

use serde::Serialize;
use serde::de::DeserializeOwned;
use serde_json::Value;

/// `base` with `patch` (a JSON object, or null for no change) merged over
/// it: nested objects merge key by key; any other value replaces the
/// base's. A key the settings do not have is refused, naming it
/// (`unknown setting "weights.gcmf"`).
pub fn patched<T: Serialize + DeserializeOwned>(base: &T, patch: &Value) -> Result<T, String> {
    fn merge(base: &mut Value, patch: &Value, at: &str) -> Result<(), String> {
        match (base, patch) {
            (Value::Object(b), Value::Object(p)) => {
                for (k, v) in p {
                    let path = if at.is_empty() { k.clone() } else { format!("{at}.{k}") };
                    let slot = b.get_mut(k).ok_or_else(|| format!("unknown setting {path:?}"))?;
                    merge(slot, v, &path)?;
                }
                Ok(())
            }
            (b, p) => {
                *b = p.clone();
                Ok(())
            }
        }
    }
    if !patch.is_object() && !patch.is_null() {
        return Err(format!("a settings patch is a JSON object, found {patch}"));
    }
    let base = serde_json::to_value(base).map_err(|e| e.to_string())?;
    let mut value = base.clone();
    if patch.is_object() {
        merge(&mut value, patch, "")?;
    }
    serde_json::from_value(value).map_err(|e| {
        // serde names no field in a wrong value ("invalid type: string
        // \"ten\", expected u32"): the first key that fails alone is named.
        let mut leaves = Vec::new();
        leaves_of(patch, "", &mut leaves);
        let at_fault = leaves.into_iter().find_map(|(path, leaf)| {
            let mut one = base.clone();
            merge(&mut one, &leaf, "").ok()?;
            serde_json::from_value::<T>(one).err().map(|e| format!("not valid settings: {path:?}: {e}"))
        });
        at_fault.unwrap_or_else(|| format!("not valid settings: {e}"))
    })
}

/// Each leaf of the object `patch` (a value that is not an object), with its
/// dotted path and a patch that holds it alone, where it stood.
fn leaves_of(patch: &Value, at: &str, out: &mut Vec<(String, Value)>) {
    let Value::Object(map) = patch else { return };
    for (k, v) in map {
        let path = if at.is_empty() { k.clone() } else { format!("{at}.{k}") };
        let mut inner = Vec::new();
        match v {
            Value::Object(_) => leaves_of(v, &path, &mut inner),
            _ => inner.push((path, v.clone())),
        }
        let wrap = |leaf: Value| Value::Object([(k.clone(), leaf)].into_iter().collect());
        out.extend(inner.into_iter().map(|(p, leaf)| (p, wrap(leaf))));
    }
}

/// Settings read from `text`: a JSON object of some of the keys, merged over
/// the defaults ([`patched`]). Anything but an object is refused (serde
/// would read an array as the fields in order), as is an unknown key.
pub fn from_json<T: Serialize + DeserializeOwned + Default>(text: &str) -> Result<T, serde_json::Error> {
    use serde::de::Error;
    let value: Value = serde_json::from_str(text)?;
    let found = match &value {
        Value::Object(_) => return patched(&T::default(), &value).map_err(serde_json::Error::custom),
        Value::Array(_) => "an array",
        Value::String(_) => "a string",
        Value::Number(_) => "a number",
        Value::Bool(_) => "a boolean",
        Value::Null => "null",
    };
    Err(serde_json::Error::custom(format!("expected a JSON object of settings, found {found}")))
}
