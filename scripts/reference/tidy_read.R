# Reads a report's trials_tidy.csv with R's read.csv as a user would (types inferred) and
# prints what it read, one line each: "column<TAB>class<TAB>missing" per column in order,
# "rows<TAB>n", then "value<TAB>column<TAB>v1<TAB>v2..." for a few columns (numbers with 17
# significant digits). Used by the study tests that
# report the examples (scripts/golden/tidy_readers.rs).
args <- commandArgs(trailingOnly = TRUE)
d <- read.csv(args[1], stringsAsFactors = FALSE)
for (n in names(d)) {
  cat(n, class(d[[n]])[1], sum(is.na(d[[n]])), sep = "\t")
  cat("\n")
}
cat("rows", nrow(d), sep = "\t")
cat("\n")
for (n in c("subject", "trial_index", "score", "response_time_ms")) {
  v <- d[[n]]
  if (is.numeric(v)) v <- sprintf("%.17g", v)
  cat("value", n, v, sep = "\t")
  cat("\n")
}
