//! Statistics over study results and the reports a paper needs.
//!
//! Holds (analysis issue): MOS, DMOS, confidence intervals, paired and Welch t-tests, BT.500
//! observer screening, staircase thresholds and psychometric fits, and the tables and plots that
//! `study report` writes.
