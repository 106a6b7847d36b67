//! Host hardware-in-the-loop tests live in `tests/`; this library is empty.
