//! The byte layout of every message, for `docs/messages.md`, the recording's JSON schemas and
//! clients in other languages, derived from the declarations ([`wire_struct!`],
//! [`wire_message!`]); and the wire-compatibility table that pins each message's layout to its
//! version (`versions.txt` beside this file).

use super::*;
use crate::arm::JointServoState;
use crate::contact::StiffnessFitState;
use crate::dither::DitherState;
use crate::hybrid::HybridState;
use crate::servo::{ContactState, EstimationCounters, SafeState, ServoState, TrackState};
use crate::tangent::ProbeSample;
use crate::tuner::TunerState;
use crate::watchdog::GateCounters;
use crate::window::{PeriodWindowState, SlidingSummary};
use crate::wire::{FieldLayout, WireMessage, WireStruct, fnv1a};
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;

/// A wire type's byte layout, for `docs/messages.md` and clients in other languages.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MessageLayout {
    /// Rust type.
    pub rust: String,
    /// The iceoryx2 type name a client must use.
    pub type_name: &'static str,
    /// The layout version (None: a part of other messages, not a payload of its own).
    pub version: Option<u32>,
    /// Total size (bytes).
    pub size: usize,
    /// Alignment (bytes).
    pub align: usize,
    /// Fields in order.
    pub fields: Vec<FieldLayout>,
    /// Every leaf, nested structs opened ([`WireStruct::flat`]).
    pub flat: Vec<FieldLayout>,
}

impl MessageLayout {
    /// The layout of a part of messages.
    pub fn part<T: WireStruct + ZeroCopySend>() -> Self {
        Self {
            rust: <T as crate::wire::WireField>::spelling(),
            // SAFETY: type_name returns the derive attribute's string.
            type_name: unsafe { <T as ZeroCopySend>::type_name() },
            version: None,
            size: core::mem::size_of::<T>(),
            align: core::mem::align_of::<T>(),
            fields: T::fields(),
            flat: T::flat(),
        }
    }

    /// The layout of a message (a payload, header or element of a service).
    pub fn message<T: WireMessage + ZeroCopySend>() -> Self {
        Self {
            version: Some(T::VERSION),
            ..Self::part::<T>()
        }
    }

    /// The iceoryx2 type name a message of this name and version must have: `afs::Name` at
    /// version 1, `afs::Name.vN` from version 2 on.
    pub fn expected_type_name(rust: &str, version: u32) -> String {
        if version <= 1 {
            format!("afs::{rust}")
        } else {
            format!("afs::{rust}.v{version}")
        }
    }

    /// A fingerprint of the flattened layout (every leaf's path, type, offset and size, the
    /// size and the alignment): what the wire-compatibility table pins.
    pub fn fingerprint(&self) -> u64 {
        let mut text = format!("{} {}\n", self.size, self.align);
        for f in &self.flat {
            text += &format!("{} {} {} {}\n", f.name, f.ty, f.offset, f.size);
        }
        fnv1a(text.as_bytes())
    }

    /// The line of the wire-compatibility table for this layout.
    pub fn table_line(&self) -> String {
        format!(
            "{} {} {} {:016x}",
            self.rust,
            self.version.unwrap_or(0),
            self.size,
            self.fingerprint()
        )
    }

    /// The layout as a Markdown table (what `docs/messages.md` shows).
    pub fn markdown(&self) -> String {
        let version = match self.version {
            Some(v) => format!("version {v}, "),
            None => String::new(),
        };
        let mut s = format!(
            "### `{}` ({version}type name `{}`, {} bytes, align {})\n\n| offset | size | type | field |\n|---:|---:|---|---|\n",
            self.rust, self.type_name, self.size, self.align
        );
        let mut end = 0;
        for f in &self.fields {
            if f.offset > end {
                s += &format!("| {end} | {} | pad | |\n", f.offset - end);
            }
            s += &format!("| {} | {} | {} | `{}` |\n", f.offset, f.size, f.ty, f.name);
            end = f.offset + f.size;
        }
        if self.size > end {
            s += &format!("| {end} | {} | pad | |\n", self.size - end);
        }
        s
    }
}

/// The layouts of every message and part, in the order `docs/messages.md` lists them.
pub fn layouts() -> Vec<MessageLayout> {
    type L = MessageLayout;
    vec![
        L::message::<WrenchSample>(),
        L::message::<PlantSample>(),
        L::message::<ServoSample>(),
        L::message::<ServoCommand>(),
        L::message::<PegSample>(),
        L::part::<PegTruthMsg>(),
        L::part::<Quantiles>(),
        L::part::<GateCounters>(),
        L::message::<LoopStats>(),
        L::message::<SensorStats>(),
        L::message::<ProbeSample>(),
        L::part::<ProbePlanMsg>(),
        L::part::<TangentParamsMsg>(),
        L::message::<TangentRequestHeader>(),
        L::message::<TangentResponse>(),
        L::message::<RotationSample>(),
        L::message::<RotationRequestHeader>(),
        L::message::<RotationResponse>(),
        L::message::<FrictionReport>(),
        L::part::<ProcessStatus>(),
        L::message::<SupervisorStatus>(),
        L::message::<BoardStartup>(),
        L::message::<ServoBatch>(),
        L::message::<WorldSnapshot>(),
        L::part::<ServoState>(),
        L::part::<EstimationCounters>(),
        L::part::<TrackState>(),
        L::part::<SafeState>(),
        L::part::<JointServoState>(),
        L::part::<HybridState>(),
        L::part::<DitherState>(),
        L::part::<TunerState>(),
        L::part::<SlidingSummary>(),
        L::part::<PeriodWindowState>(),
        L::part::<InsertionState>(),
        L::part::<ContactState>(),
        L::part::<StiffnessFitState>(),
    ]
}

/// The wire-compatibility table: one line per layout a message has had at a version
/// (`Name version size fingerprint`), kept when the version moves on.
pub const VERSIONS: &str = include_str!("versions.txt");

/// Checks every message of `layouts` against the `table`: its line must be there, and a
/// message whose layout changed without a new version is named with both fingerprints.
pub fn check_versions(layouts: &[MessageLayout], table: &str) -> Result<(), String> {
    let known: Vec<Vec<&str>> = table
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .map(|l| l.split_whitespace().collect())
        .collect();
    let mut errors = Vec::new();
    for l in layouts.iter().filter(|l| l.version.is_some()) {
        let line = l.table_line();
        let want: Vec<&str> = line.split_whitespace().collect();
        let same_version = known
            .iter()
            .find(|k| k.len() == 4 && k[0] == want[0] && k[1] == want[1]);
        match same_version {
            Some(k) if *k == want => {}
            Some(k) => errors.push(format!(
                "{} changed its layout at version {} (table: {} bytes, fingerprint {}; now {} bytes, {}): bump its VERSION and add the line `{line}`",
                l.rust, want[1], k[2], k[3], want[2], want[3]
            )),
            None => errors.push(format!(
                "{} version {} is not in the table: add the line `{line}`",
                l.rust, want[1]
            )),
        }
    }
    if errors.is_empty() {
        Ok(())
    } else {
        Err(errors.join("\n"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// docs/messages.md shows every message's layout exactly as compiled (regenerate it with
    /// `afs messages` after changing a message), and every field is listed: the fields' sizes
    /// plus padding add up to the size.
    #[test]
    fn layouts_match_the_documentation() {
        let doc = include_str!("../../../docs/messages.md");
        for l in layouts() {
            let listed: usize = l.fields.iter().map(|f| f.size).sum();
            assert!(listed <= l.size, "{}", l.rust);
            let last = l.fields.last().map_or(0, |f| f.offset + f.size);
            assert!(
                l.size - last < l.align,
                "{}: a field is missing at the end",
                l.rust
            );
            for w in l.fields.windows(2) {
                assert!(
                    w[1].offset - (w[0].offset + w[0].size) < 8,
                    "{}: a field is missing before {}",
                    l.rust,
                    w[1].name
                );
            }
            assert!(
                doc.contains(&l.markdown()),
                "docs/messages.md is out of date for {}; run `afs messages`:\n{}",
                l.rust,
                l.markdown()
            );
        }
    }

    /// Every message's layout is the one the wire-compatibility table pins for its version.
    #[test]
    fn every_layout_is_pinned_to_its_version() {
        if let Err(e) = check_versions(&layouts(), VERSIONS) {
            panic!("{e}");
        }
    }

    /// A layout that changes without a new version fails the check, naming the message; one
    /// with a new version and its line passes; a new message needs its line.
    #[test]
    fn a_layout_change_without_a_new_version_is_refused() {
        let all = layouts();
        let mut changed = all.clone();
        let s = changed
            .iter_mut()
            .find(|l| l.rust == "ServoSample")
            .expect("ServoSample");
        s.size += 8;
        let e = check_versions(&changed, VERSIONS).unwrap_err();
        assert!(e.contains("ServoSample changed its layout"), "{e}");
        assert!(!e.contains("PlantSample"), "{e}");
        let s = changed
            .iter_mut()
            .find(|l| l.rust == "ServoSample")
            .unwrap();
        s.version = Some(99);
        let line = s.table_line();
        let e = check_versions(&changed, VERSIONS).unwrap_err();
        assert!(
            e.contains("ServoSample version 99 is not in the table"),
            "{e}"
        );
        let table = format!("{VERSIONS}\n{line}\n");
        assert_eq!(check_versions(&changed, &table), Ok(()));
        // A swap of two fields of the same size keeps the size but not the fingerprint.
        let mut swapped = all.clone();
        let p = swapped
            .iter_mut()
            .find(|l| l.rust == "PlantSample")
            .unwrap();
        let (a, b) = (p.flat[5].offset, p.flat[6].offset);
        (p.flat[5].offset, p.flat[6].offset) = (b, a);
        assert!(check_versions(&swapped, VERSIONS).is_err());
    }

    /// Each message's iceoryx2 type name carries its version from version 2 on, so that
    /// iceoryx2 refuses a client built for another version when it opens the service.
    #[test]
    fn type_names_carry_the_version() {
        for l in layouts() {
            if let Some(v) = l.version {
                assert_eq!(
                    l.type_name,
                    MessageLayout::expected_type_name(&l.rust, v),
                    "{}",
                    l.rust
                );
            }
        }
        let t = MessageLayout::expected_type_name;
        assert_eq!(
            (t("WrenchSample", 1), t("ServoSample", 2)),
            ("afs::WrenchSample".into(), "afs::ServoSample.v2".into())
        );
    }

    /// Nested parts and arrays flatten to their leaves, in C's spelling.
    #[test]
    fn layouts_flatten_nested_parts_in_c_spelling() {
        let w = MessageLayout::message::<WorldSnapshot>();
        assert!(
            w.flat.iter().any(|f| f.name == "controller.hybrid.s_m"),
            "{:?}",
            w.flat
        );
        let b = MessageLayout::message::<ServoBatch>();
        assert!(b.flat.iter().any(|f| f.name == "samples[200].seq"));
        let r = MessageLayout::message::<RotationRequestHeader>();
        let c = r.fields.iter().find(|f| f.name == "centre_m").unwrap();
        assert_eq!((c.ty.as_str(), c.size), ("f64[6][2]", 96));
        for l in layouts() {
            let leaves: usize = l.flat.iter().map(|f| f.size).sum();
            assert!(leaves <= l.size, "{}", l.rust);
        }
    }
}
