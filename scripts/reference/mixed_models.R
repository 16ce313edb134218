# Reference fits for `study report`'s mixed models (analysis/src/mixed.rs, clmm.rs), run by
# report/tests/mixed_interop.rs.
#
#   Rscript scripts/reference/mixed_models.R RATINGS.csv FIXED RANDOM ORDINAL
#
# RATINGS.csv: one row per rating with columns subject, clip, score and method (or codec) and
#   ratio (or compression_ratio), as `study report` writes ratings.csv; rows without a ratio
#   (references) are left out, as the report leaves them out.
# FIXED: the fixed part, e.g. "method * ratio"; RANDOM: the random part, e.g.
#   "(1 | subject) + (1 | clip)"; ORDINAL: "yes" to fit the cumulative link mixed model too
#   (random intercepts of subject, and of clip with three clips or more) with its
#   likelihood-ratio tests, "fit" for the model alone, "no" for none.
#
# Prints CSV rows `model,kind,name,value` with 17 significant digits:
#   lmer,fixef|se,NAME       REML fit's coefficients and standard errors
#   lmer,var,GROUP/NAME      variance components (Residual/ for the residual)
#   lmer,theta,I / lmer,reml,criterion / lmer,loglik,
#   lmer_lrt,chisq|df,TERM   ML refits, anova(update(m, . ~ . - TERM), m)
#   clmm,coef|se,NAME        thresholds and fixed effects (coef(m), vcov(m)); clmm,var,GROUP
#   clmm,loglik, ; clmm_lrt,chisq|df,TERM
# Factors' levels are in byte order (sort(method = "radix")), as the report orders them, so
# the treatment contrasts have the same baseline whatever the locale.

suppressPackageStartupMessages({
  library(lme4)
  library(ordinal)
})

args <- commandArgs(trailingOnly = TRUE)
if (length(args) < 4) stop("usage: mixed_models.R RATINGS.csv FIXED RANDOM ORDINAL")
d <- read.csv(args[1], stringsAsFactors = FALSE, check.names = FALSE)
if (!"method" %in% names(d)) d$method <- d$codec
if (!"ratio" %in% names(d)) d$ratio <- d$compression_ratio
d <- d[!is.na(d$ratio) & d$ratio != "", ]
d$ratio <- as.numeric(d$ratio)
radix <- function(x) factor(x, levels = sort(unique(x), method = "radix"))
d$subject <- radix(as.character(d$subject))
d$clip <- radix(as.character(d$clip))
d$method <- radix(as.character(d$method))
d$ratio <- factor(d$ratio, levels = sort(unique(d$ratio)))
fixed <- args[2]
random <- args[3]

out <- function(model, kind, name, value) {
  cat(sprintf("%s,%s,%s,%.17g\n", model, kind, name, value))
}

# Tight tolerances, so R's optimum is the reference and not R's own tolerance; and two
# optimizers, keeping the lower criterion (as lme4's allFit() compares them): with a random
# slope the criterion can have a second, higher local minimum on the boundary, where bobyqa
# alone sometimes stops.
controls <- list(
  lmerControl(optimizer = "bobyqa", optCtrl = list(rhoend = 1e-10, maxfun = 1e5),
              check.conv.singular = "ignore", check.conv.grad = "ignore"),
  lmerControl(optimizer = "Nelder_Mead",
              optCtrl = list(FtolAbs = 1e-12, FtolRel = 1e-15, XtolRel = 1e-10, maxfun = 1e5),
              check.conv.singular = "ignore", check.conv.grad = "ignore"))
best_lmer <- function(form, reml) {
  fits <- lapply(controls, function(ctrl) lmer(form, data = d, REML = reml, control = ctrl))
  crit <- sapply(fits, function(f) if (reml) REMLcrit(f) else deviance(f))
  fits[[which.min(crit)]]
}
form <- as.formula(paste("score ~", fixed, "+", random))
m <- best_lmer(form, TRUE)
cat("model,kind,name,value\n")
fe <- fixef(m)
se <- sqrt(diag(as.matrix(vcov(m))))
for (i in seq_along(fe)) {
  out("lmer", "fixef", names(fe)[i], fe[i])
  out("lmer", "se", names(fe)[i], se[i])
}
vc <- as.data.frame(VarCorr(m))
for (i in seq_len(nrow(vc))) {
  if (is.na(vc$var2[i])) {
    name <- if (is.na(vc$var1[i])) "" else vc$var1[i]
    out("lmer", "var", paste0(vc$grp[i], "/", name), vc$vcov[i])
  }
}
th <- getME(m, "theta")
for (i in seq_along(th)) out("lmer", "theta", i, th[i])
out("lmer", "reml", "criterion", REMLcrit(m))
out("lmer", "loglik", "", as.numeric(logLik(m)))

terms_of <- function(f) attr(terms(as.formula(paste("~", f))), "term.labels")
tests <- function(full_terms) {
  # The interaction against the additive model; each main effect in the additive model.
  labs <- terms_of(full_terms)
  additive <- setdiff(labs, "method:ratio")
  rhs <- function(t) if (length(t) == 0) "1" else paste(t, collapse = " + ")
  res <- list()
  if ("method:ratio" %in% labs) res[["method:ratio"]] <- list(rhs(labs), rhs(additive))
  for (t in intersect(c("method", "ratio"), additive)) {
    res[[t]] <- list(rhs(additive), rhs(setdiff(additive, t)))
  }
  res
}

ml <- list()
fit_ml <- function(f) {
  if (is.null(ml[[f]])) {
    ml[[f]] <<- best_lmer(as.formula(paste("score ~", f, "+", random)), FALSE)
  }
  ml[[f]]
}
for (t in names(tests(fixed))) {
  pair <- tests(fixed)[[t]]
  full <- fit_ml(pair[[1]])
  reduced <- fit_ml(pair[[2]])
  out("lmer_lrt", "chisq", t, 2 * (as.numeric(logLik(full)) - as.numeric(logLik(reduced))))
  out("lmer_lrt", "df", t, length(fixef(full)) - length(fixef(reduced)))
}

if (args[4] %in% c("yes", "fit")) {
  d$category <- factor(d$score, levels = sort(unique(d$score)), ordered = TRUE)
  # ordinal's clmm takes a grouping factor of three levels or more: with two clips the
  # ordinal model has the subject intercept only, as the report's.
  intercepts <- if (nlevels(d$clip) >= 3) "(1 | subject) + (1 | clip)" else "(1 | subject)"
  cctrl <- clmm.control(method = "nlminb", gradTol = 1e-10, rel.tol = 1e-13, eval.max = 2000,
                        iter.max = 1000)
  fit_clmm <- function(f, hess = FALSE) {
    clmm(as.formula(paste("category ~", f, "+", intercepts)), data = d, link = "logit",
         Hess = hess, control = cctrl)
  }
  c1 <- fit_clmm(fixed, hess = TRUE)
  cf <- coef(c1)
  cse <- sqrt(diag(vcov(c1)))
  for (n in names(cf)) {
    out("clmm", "coef", n, cf[n])
    out("clmm", "se", n, cse[n])
  }
  for (g in names(c1$ST)) out("clmm", "var", g, c1$ST[[g]][1, 1]^2)
  out("clmm", "loglik", "", as.numeric(logLik(c1)))
  cm <- list()
  cm[[fixed]] <- c1
  for (t in if (args[4] == "yes") names(tests(fixed)) else character(0)) {
    pair <- tests(fixed)[[t]]
    for (f in pair) if (is.null(cm[[f]])) cm[[f]] <- fit_clmm(f)
    out("clmm_lrt", "chisq", t,
        2 * (as.numeric(logLik(cm[[pair[[1]]]])) - as.numeric(logLik(cm[[pair[[2]]]]))))
  }
}
