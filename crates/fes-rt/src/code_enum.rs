//! `code_enum!`: a `#[repr(u8)]` enumeration and the decoding of its codes, for the
//! message enumerations ([`crate::msg`]) and the real-time ones ([`crate::rt`]) alike.

/// Declares a `#[repr(u8)]` enumeration and `from_code`, the variant of a code (`None` for
/// any other), so the codes stand once, in the declaration, and every decoding (a
/// `TryFrom<u8>` with its own error, a fallback variant) goes through the same match.
macro_rules! code_enum {
    (
        $(#[$meta:meta])*
        pub enum $name:ident {
            $($(#[$vmeta:meta])* $variant:ident = $code:literal,)+
        }
    ) => {
        $(#[$meta])*
        #[repr(u8)]
        pub enum $name {
            $($(#[$vmeta])* $variant = $code,)+
        }

        impl $name {
            /// The variant whose code is `code`, if any.
            pub(crate) const fn from_code(code: u8) -> Option<Self> {
                match code {
                    $($code => Some(Self::$variant),)+
                    _ => None,
                }
            }
        }
    };
}
pub(crate) use code_enum;
