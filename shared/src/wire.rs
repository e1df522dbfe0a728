//! The wire format's building blocks: codes and flags (numbers in the messages, enums and
//! flag sets in the code), and the structs that cross the wire, declared once with their
//! byte layout, finiteness check and layout version derived from the declaration.

/// Declares an enum whose variants are `u32` codes on the wire, with `From<E> for u32` and
/// `TryFrom<u32> for E`; an unknown code is refused and given back, for the reader to count.
macro_rules! wire_code {
    (
        $(#[$m:meta])*
        $vis:vis enum $name:ident {
            $($(#[$vm:meta])* $variant:ident = $code:literal),+ $(,)?
        }
    ) => {
        $(#[$m])*
        #[repr(u32)]
        $vis enum $name {
            $($(#[$vm])* $variant = $code),+
        }

        impl From<$name> for u32 {
            fn from(v: $name) -> u32 {
                v as u32
            }
        }

        impl TryFrom<u32> for $name {
            type Error = u32;
            fn try_from(c: u32) -> Result<Self, u32> {
                match c {
                    $($code => Ok($name::$variant),)+
                    _ => Err(c),
                }
            }
        }
    };
}

/// Declares a set of flags that is a `u32` on the wire (`bitflags`, `#[repr(transparent)]`),
/// with what a message field needs: zero-copy, and serialised as the number itself (the
/// layout and the recording's JSON schema say `u32`).
macro_rules! wire_flags {
    (
        $(#[$m:meta])*
        $vis:vis struct $name:ident {
            $($(#[$($fm:tt)*])* const $flag:ident = $value:expr;)+
        }
    ) => {
        bitflags::bitflags! {
            $(#[$m])*
            #[repr(transparent)]
            #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
            $vis struct $name: u32 {
                $($(#[$($fm)*])* const $flag = $value;)+
            }
        }

        // SAFETY: #[repr(transparent)] over a u32: plain data with one layout everywhere.
        unsafe impl iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend for $name {}

        impl $crate::wire::WireField for $name {
            fn spelling() -> String {
                "u32".to_string()
            }
        }

        impl serde::Serialize for $name {
            fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
                s.serialize_u32(self.bits())
            }
        }

        impl<'de> serde::Deserialize<'de> for $name {
            fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
                Ok(Self::from_bits_retain(<u32 as serde::Deserialize>::deserialize(d)?))
            }
        }
    };
}

/// Declares a `#[repr(C)]` struct that crosses the wire (or is part of one that does), with
/// its byte layout and a finiteness check derived from the one field list: the layout that
/// `docs/messages.md` shows and the wire-compatibility table pins ([`WireStruct::fields`],
/// [`WireField::flatten`]), and [`WireField::all_finite`] over every number in it.
macro_rules! wire_struct {
    (
        $(#[$m:meta])*
        pub struct $name:ident {
            $($(#[$fm:meta])* pub $field:ident : $fty:ty),* $(,)?
        }
    ) => {
        $(#[$m])*
        #[repr(C)]
        pub struct $name {
            $($(#[$fm])* pub $field: $fty),*
        }

        impl $crate::wire::WireField for $name {
            const LEAF: bool = false;

            fn spelling() -> String {
                stringify!($name).to_string()
            }

            fn all_finite(&self) -> bool {
                true $(&& $crate::wire::WireField::all_finite(&self.$field))*
            }

            fn flatten(prefix: &str, base: usize, out: &mut Vec<$crate::wire::FieldLayout>) {
                $(
                    <$fty as $crate::wire::WireField>::flatten(
                        &$crate::wire::path(prefix, stringify!($field)),
                        base + core::mem::offset_of!($name, $field),
                        out,
                    );
                )*
            }
        }

        impl $crate::wire::WireStruct for $name {
            fn fields() -> Vec<$crate::wire::FieldLayout> {
                vec![$($crate::wire::FieldLayout {
                    name: stringify!($field).to_string(),
                    ty: <$fty as $crate::wire::WireField>::spelling(),
                    offset: core::mem::offset_of!($name, $field),
                    size: core::mem::size_of::<$fty>(),
                }),*]
            }
        }
    };
}

/// A [`wire_struct!`] that is a service's payload (or the header or element of one), with its
/// layout version: `Name::VERSION`, which the message's `version` field carries (where it has
/// one) and its iceoryx2 type name ends with (`afs::Name` at version 1, `afs::Name.vN` from
/// version 2 on), so that iceoryx2 refuses a client built for another version when it opens
/// the service. Changing the layout means bumping the version (docs/messages.md).
macro_rules! wire_message {
    (
        version = $v:literal;
        $(#[$m:meta])*
        pub struct $name:ident { $($body:tt)* }
    ) => {
        wire_struct! { $(#[$m])* pub struct $name { $($body)* } }

        impl $name {
            /// The layout version of this message (docs/messages.md); a reader refuses others.
            pub const VERSION: u32 = $v;
        }

        impl $crate::wire::WireMessage for $name {
            const VERSION: u32 = $v;
        }
    };
}

/// One field of a wire type's byte layout.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FieldLayout {
    /// Field name (in a flattened layout, its path: `hybrid.s_m`, `samples[50].seq`).
    pub name: String,
    /// Type as a C-like spelling (`f64[2]` is two f64, `f64[6][2]` six pairs).
    pub ty: String,
    /// Byte offset.
    pub offset: usize,
    /// Byte size.
    pub size: usize,
}

/// A type that can be a field of a wire struct: how docs/messages.md spells it, its leaves
/// (numbers, flags, arrays of them) with their offsets, and whether its numbers are finite.
pub trait WireField {
    /// A number, flags or an array of them (not a struct to look into).
    const LEAF: bool = true;

    /// The C-like spelling of the type.
    fn spelling() -> String;

    /// True when every floating-point number in it is finite.
    fn all_finite(&self) -> bool {
        true
    }

    /// Appends its leaves, named from `prefix`, at byte offset `base`.
    fn flatten(prefix: &str, base: usize, out: &mut Vec<FieldLayout>)
    where
        Self: Sized,
    {
        out.push(FieldLayout {
            name: prefix.to_string(),
            ty: Self::spelling(),
            offset: base,
            size: core::mem::size_of::<Self>(),
        });
    }
}

/// A wire struct's own fields, in order ([`wire_struct!`]).
pub trait WireStruct: WireField + Sized {
    /// Its fields (not flattened).
    fn fields() -> Vec<FieldLayout>;

    /// Every leaf of it, nested structs opened, arrays of structs opened at their first
    /// element (`samples[50].seq`).
    fn flat() -> Vec<FieldLayout> {
        let mut out = Vec::new();
        Self::flatten("", 0, &mut out);
        out
    }
}

/// A service's payload, header or element ([`wire_message!`]).
pub trait WireMessage: WireStruct {
    /// Its layout version.
    const VERSION: u32;
}

/// `prefix.field`, or `field` at the top.
pub fn path(prefix: &str, field: &str) -> String {
    if prefix.is_empty() {
        field.to_string()
    } else {
        format!("{prefix}.{field}")
    }
}

macro_rules! leaf {
    ($($t:ty => $s:literal),* $(,)?) => {
        $(impl WireField for $t {
            fn spelling() -> String {
                $s.to_string()
            }
        })*
    };
}

leaf!(u8 => "u8", u32 => "u32", u64 => "u64", i32 => "i32", bool => "bool");

impl WireField for f64 {
    fn spelling() -> String {
        "f64".to_string()
    }

    fn all_finite(&self) -> bool {
        self.is_finite()
    }
}

impl<T: WireField, const N: usize> WireField for [T; N] {
    const LEAF: bool = T::LEAF;

    /// C's order: `[[f64; 2]; 6]` is `f64[6][2]`.
    fn spelling() -> String {
        let inner = T::spelling();
        match inner.find('[') {
            Some(i) => format!("{}[{N}]{}", &inner[..i], &inner[i..]),
            None => format!("{inner}[{N}]"),
        }
    }

    fn all_finite(&self) -> bool {
        self.iter().all(WireField::all_finite)
    }

    fn flatten(prefix: &str, base: usize, out: &mut Vec<FieldLayout>) {
        if T::LEAF {
            out.push(FieldLayout {
                name: prefix.to_string(),
                ty: Self::spelling(),
                offset: base,
                size: core::mem::size_of::<Self>(),
            });
        } else {
            T::flatten(&format!("{prefix}[{N}]"), base, out);
        }
    }
}

/// A 64-bit FNV-1a hash: the fingerprint of a flattened layout in the wire-compatibility table.
/// (Hand-written: eight lines, where std's hashers are not stable across releases.)
pub fn fnv1a(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in bytes {
        h ^= u64::from(*b);
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    h
}
