//! Wire codes and flags: numbers in the messages, enums and flag sets in the code.

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
