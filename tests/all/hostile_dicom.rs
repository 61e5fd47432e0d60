//! Issue 57 regression tests (hostile_dicom).
