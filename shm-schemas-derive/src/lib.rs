//! `#[derive(Payload)]`: everything a type needs to travel on a nerve port,
//! from one derive on a `#[repr(C)]` struct with named fields:
//!
//! * its stable type name (`#[payload(name = "nerve::Tick")]`), the one
//!   iceoryx2 compares when a port opens a service;
//! * `ZeroCopySend`, with a compile-time check that every field is
//!   `ZeroCopySend` too;
//! * its schema (`shm_schemas::schema::Described`): field names, offsets as
//!   the compiler laid them out (`offset_of!`), and each field's own schema,
//!   from which the layout's fingerprint is computed;
//! * `shm_schemas::Payload`;
//! * `shm_schemas::schema::AnyBitPattern`: any bytes are a valid value of
//!   the type, because a sample's bytes may come from a recording, a bridge
//!   peer or Python rather than from Rust. Every field must be
//!   `AnyBitPattern` (numbers, arrays, `FixedName`, `shm_schemas::Bool`,
//!   other payloads), so `bool`, `char` and enums are refused: store a `u8`
//!   (0/1) or a `shm_schemas::Bool` for a flag, a `u8` code for an enum.
//!   And the type has no implicit padding (checked at compile time, field
//!   by field): padding bytes are never written, so a sample's bytes would
//!   hold uninitialised memory. Write the padding as fields whose name
//!   starts with `_pad`, of type `[u8; N]` (give them `#[serde(skip)]`):
//!   they are left out of the schema, as the compiler's padding was, so the
//!   layout fingerprint does not change.
//!
//! ```ignore
//! #[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, shm_schemas::Payload)]
//! #[repr(C)]
//! #[payload(name = "lab::Gripper")]
//! pub struct Gripper {
//!     pub width_m: f32,
//!     pub force_n: f32,
//! }
//! ```
//!
//! The generated code names `::shm_schemas`: a crate that derives `Payload`
//! depends on `shm-schemas`.

use proc_macro::TokenStream;
use quote::quote;
use syn::{Data, DeriveInput, Fields, LitStr, parse_macro_input, spanned::Spanned};

/// Derives `ZeroCopySend`, `Described` and `Payload`; see the crate's documentation.
#[proc_macro_derive(Payload, attributes(payload))]
pub fn derive_payload(input: TokenStream) -> TokenStream {
    let input = parse_macro_input!(input as DeriveInput);
    match expand(&input) {
        Ok(ts) => ts.into(),
        Err(e) => e.to_compile_error().into(),
    }
}

fn expand(input: &DeriveInput) -> syn::Result<proc_macro2::TokenStream> {
    let ident = &input.ident;
    if !input.generics.params.is_empty() {
        return Err(syn::Error::new(
            input.generics.span(),
            "a payload cannot be generic: its layout and type name must be fixed",
        ));
    }
    if !is_repr_c(input)? {
        return Err(syn::Error::new(
            ident.span(),
            "a payload must be #[repr(C)]: its layout is shared between processes and builds",
        ));
    }
    let name = type_name(input)?;
    let Data::Struct(data) = &input.data else {
        return Err(syn::Error::new(
            ident.span(),
            "#[derive(Payload)] takes a struct with named fields (enums travel as their integer: store a u8 code)",
        ));
    };
    let Fields::Named(fields) = &data.fields else {
        return Err(syn::Error::new(data.fields.span(), "#[derive(Payload)] takes a struct with named fields"));
    };
    for f in &fields.named {
        refuse_invalid_bit_patterns(&f.ty)?;
        if f.ident.as_ref().is_some_and(is_padding) && !is_byte_array(&f.ty) {
            return Err(syn::Error::new(f.ty.span(), "a `_pad` field is explicit padding: its type must be [u8; N]"));
        }
    }
    let all_idents: Vec<_> = fields.named.iter().filter_map(|f| f.ident.as_ref()).collect();
    let all_types: Vec<_> = fields.named.iter().map(|f| &f.ty).collect();
    // the schema leaves the explicit padding out, as it left the compiler's
    let described: Vec<_> = fields.named.iter().filter(|f| f.ident.as_ref().is_some_and(|i| !is_padding(i))).collect();
    let field_idents: Vec<_> = described.iter().filter_map(|f| f.ident.as_ref()).collect();
    let field_types: Vec<_> = described.iter().map(|f| &f.ty).collect();
    let field_names: Vec<String> = field_idents.iter().map(|i| i.to_string()).collect();
    let gap_before: Vec<LitStr> = all_idents
        .iter()
        .map(|f| {
            LitStr::new(
                &format!(
                    "#[derive(Payload)] {ident}: the compiler pads before field `{f}`, and padding bytes are never \
                     written: add a field `_pad…: [u8; N]` before `{f}` (N: the gap) so that every byte is a field's"
                ),
                f.span(),
            )
        })
        .collect();
    let gap_after = LitStr::new(
        &format!(
            "#[derive(Payload)] {ident}: the compiler pads after the last field (the size is rounded up to the \
             alignment), and padding bytes are never written: add a last field `_pad…: [u8; N]` (N: the gap)"
        ),
        ident.span(),
    );
    Ok(quote! {
        // SAFETY: the type is #[repr(C)], not generic, and every field is
        // ZeroCopySend (checked below), which is what ZeroCopySend requires.
        unsafe impl ::shm_schemas::__private::ZeroCopySend for #ident {
            unsafe fn type_name() -> &'static str {
                #name
            }
        }

        const _: () = {
            fn every_field_is_zero_copy_send_and_any_bit_pattern() {
                fn check<T: ::shm_schemas::__private::ZeroCopySend + ::shm_schemas::schema::AnyBitPattern>() {}
                #( check::<#all_types>(); )*
            }
        };

        // no implicit padding: each field starts where the one before it ends
        const _: () = {
            let mut end = 0usize;
            #(
                if ::core::mem::offset_of!(#ident, #all_idents) != end {
                    ::core::panic!(#gap_before);
                }
                end = ::core::mem::offset_of!(#ident, #all_idents) + ::core::mem::size_of::<#all_types>();
            )*
            if end != ::core::mem::size_of::<#ident>() {
                ::core::panic!(#gap_after);
            }
        };

        // SAFETY: every field is AnyBitPattern (checked above) and no byte
        // lies outside a field (checked above), so any bytes are a valid value
        unsafe impl ::shm_schemas::schema::AnyBitPattern for #ident {}

        impl ::shm_schemas::schema::Described for #ident {
            fn schema() -> ::shm_schemas::schema::Schema {
                ::shm_schemas::schema::Schema {
                    type_name: ::std::string::String::from(#name),
                    size: ::core::mem::size_of::<#ident>(),
                    align: ::core::mem::align_of::<#ident>(),
                    kind: ::shm_schemas::schema::Kind::Struct {
                        fields: ::std::vec![
                            #( ::shm_schemas::schema::Field {
                                name: ::std::string::String::from(#field_names),
                                offset: ::core::mem::offset_of!(#ident, #field_idents),
                                schema: <#field_types as ::shm_schemas::schema::Described>::schema(),
                            } ),*
                        ],
                    },
                }
            }
        }

        impl ::shm_schemas::Payload for #ident {}
    })
}

/// Refuses `bool` and `char` (alone or in arrays) with what to store
/// instead; enums and other types without every bit pattern valid are
/// refused by the `AnyBitPattern` bound.
fn refuse_invalid_bit_patterns(ty: &syn::Type) -> syn::Result<()> {
    match ty {
        syn::Type::Array(a) => refuse_invalid_bit_patterns(&a.elem),
        syn::Type::Paren(p) => refuse_invalid_bit_patterns(&p.elem),
        syn::Type::Group(g) => refuse_invalid_bit_patterns(&g.elem),
        syn::Type::Path(p) if p.qself.is_none() && p.path.is_ident("bool") => Err(syn::Error::new(
            ty.span(),
            "a payload field cannot be a bool: a recording, a bridge peer or Python may write any byte, and a bool \
             other than 0 or 1 is undefined behaviour; store a u8 (0/1), or use shm_schemas::Bool (same schema)",
        )),
        syn::Type::Path(p) if p.qself.is_none() && p.path.is_ident("char") => Err(syn::Error::new(
            ty.span(),
            "a payload field cannot be a char: not every u32 is a char; store a u32, or text in a FixedName",
        )),
        _ => Ok(()),
    }
}

/// Whether a field is explicit padding (`_pad`, `_pad0`, `_pad_tail` ...).
fn is_padding(ident: &syn::Ident) -> bool {
    ident.to_string().starts_with("_pad")
}

/// Whether `ty` is `[u8; N]`.
fn is_byte_array(ty: &syn::Type) -> bool {
    matches!(ty, syn::Type::Array(a) if matches!(&*a.elem, syn::Type::Path(p) if p.qself.is_none() && p.path.is_ident("u8")))
}

/// Whether the type carries `#[repr(C)]` (possibly with `align(N)`).
fn is_repr_c(input: &DeriveInput) -> syn::Result<bool> {
    let mut c = false;
    for attr in input.attrs.iter().filter(|a| a.path().is_ident("repr")) {
        attr.parse_nested_meta(|meta| {
            if meta.path.is_ident("C") {
                c = true;
            } else if meta.input.peek(syn::token::Paren) {
                // align(N) and the like
                let content;
                syn::parenthesized!(content in meta.input);
                let _: proc_macro2::TokenStream = content.parse()?;
            }
            Ok(())
        })?;
    }
    Ok(c)
}

/// The `name` of `#[payload(name = "...")]`.
fn type_name(input: &DeriveInput) -> syn::Result<LitStr> {
    let mut name = None;
    for attr in input.attrs.iter().filter(|a| a.path().is_ident("payload")) {
        attr.parse_nested_meta(|meta| {
            if meta.path.is_ident("name") {
                let lit: LitStr = meta.value()?.parse()?;
                if lit.value().is_empty() {
                    return Err(meta.error("the payload's name cannot be empty"));
                }
                name = Some(lit);
                Ok(())
            } else {
                Err(meta.error("unknown payload attribute: the one known is `name = \"crate::Type\"`"))
            }
        })?;
    }
    name.ok_or_else(|| {
        syn::Error::new(
            input.ident.span(),
            "a payload needs its stable type name: add #[payload(name = \"your_crate::TypeName\")]",
        )
    })
}
