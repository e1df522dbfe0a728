//! Reading back the reports' figures: JSON has no NaN, so serde_json writes an undefined figure
//! (the mean of nothing, a ratio to an empty histogram) as `null`. A figure field carries
//! `#[serde(deserialize_with = "afs_shared::nan::or_null")]` to read that `null` back as NaN,
//! so that every report round-trips.

use serde::{Deserialize, Deserializer};

/// A number, or NaN for `null`.
pub fn or_null<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

/// A pair of numbers (a range, a point), each NaN for `null`.
pub fn pair_or_null<'de, D: Deserializer<'de>>(d: D) -> Result<[f64; 2], D::Error> {
    let v = <[Option<f64>; 2]>::deserialize(d)?;
    Ok(v.map(|x| x.unwrap_or(f64::NAN)))
}

#[cfg(test)]
mod tests {
    use serde::{Deserialize, Serialize};

    #[derive(Serialize, Deserialize)]
    struct Figure {
        #[serde(deserialize_with = "super::or_null")]
        x: f64,
        #[serde(deserialize_with = "super::pair_or_null")]
        pair: [f64; 2],
    }

    #[test]
    fn nan_round_trips_through_null() {
        let f = Figure {
            x: f64::NAN,
            pair: [1.0, f64::NAN],
        };
        let text = serde_json::to_string(&f).unwrap();
        assert_eq!(text, r#"{"x":null,"pair":[1.0,null]}"#);
        let back: Figure = serde_json::from_str(&text).unwrap();
        assert!(back.x.is_nan() && back.pair[0] == 1.0 && back.pair[1].is_nan());
        let plain: Figure = serde_json::from_str(r#"{"x":2.5,"pair":[3,4]}"#).unwrap();
        assert_eq!((plain.x, plain.pair), (2.5, [3.0, 4.0]));
        assert!(serde_json::from_str::<Figure>(r#"{"x":"a","pair":[1,2]}"#).is_err());
        assert!(serde_json::from_str::<Figure>(r#"{"x":1,"pair":[1]}"#).is_err());
    }
}
