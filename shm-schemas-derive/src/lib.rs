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
//! * `shm_schemas::Payload`.
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
    let field_idents: Vec<_> = fields.named.iter().filter_map(|f| f.ident.as_ref()).collect();
    let field_types: Vec<_> = fields.named.iter().map(|f| &f.ty).collect();
    let field_names: Vec<String> = field_idents.iter().map(|i| i.to_string()).collect();
    Ok(quote! {
        // SAFETY: the type is #[repr(C)], not generic, and every field is
        // ZeroCopySend (checked below), which is what ZeroCopySend requires.
        unsafe impl ::shm_schemas::__private::ZeroCopySend for #ident {
            unsafe fn type_name() -> &'static str {
                #name
            }
        }

        const _: () = {
            fn every_field_is_zero_copy_send() {
                fn check<T: ::shm_schemas::__private::ZeroCopySend>() {}
                #( check::<#field_types>(); )*
            }
        };

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
