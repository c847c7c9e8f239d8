# Reproduce `study analyze`'s main tables from `study export` output alone.
#
#   Rscript reproduce.R export/ [out/]
#
# reads export/trials.csv and export/tlx.csv and writes to out/ (default: export/r/):
#   comparisons.csv  HV vs VO within each group, Holm within task x measure: the test,
#                    the mean difference with its 95 % CI, d_z with its CI, Hedges'
#                    g_av, the rank-biserial r and the JZS Bayes factor BF10
#   success.csv      task success per group, the exact McNemar test, Holm within task
#   anova.csv        the mixed ANOVA on participant means (afex, Type II as study's default)
#   lmm.csv          the mixed model over all trials (lmerTest, Satterthwaite df)
#   emmeans.csv      the condition's marginal means over the groups and HV - VO (emmeans)
#   design_checks.csv  the crossover's period, carry-over and trial position (lmerTest),
#                    Holm over every check of the study
# Needs R >= 4.2 with afex, lmerTest, emmeans, coin and BayesFactor (Debian: r-cran-afex,
# r-cran-lmertest, r-cran-emmeans, r-cran-coin, r-cran-bayesfactor).
suppressPackageStartupMessages({
  library(afex)
  library(lmerTest)
  library(emmeans)
  library(coin)
  library(BayesFactor)
})

args <- commandArgs(trailingOnly = TRUE)
dir <- if (length(args) >= 1) args[1] else "export"
out <- if (length(args) >= 2) args[2] else file.path(dir, "r")
dir.create(out, showWarnings = FALSE, recursive = TRUE)

trials <- read.csv(file.path(dir, "trials.csv"), stringsAsFactors = FALSE)
tlx <- read.csv(file.path(dir, "tlx.csv"), stringsAsFactors = FALSE)
# `included` is "yes" for what the analysis used, else the reason it was left out
trials <- trials[trials$included == "yes", ]
tlx <- tlx[tlx$included == "yes", ]

keys <- c("participant", "group", "task", "condition", "trial")
provenance <- c("block", "data_source", "driver", "withdrawn", "valid",
                "invalid_reason", "included", "success")
measures <- setdiff(names(trials), c(keys, provenance))

# long format: one row per trial and measure
long_trials <- do.call(rbind, lapply(measures, function(m) {
  d <- trials[!is.na(trials[[m]]), c(keys, "block")]
  if (!nrow(d)) return(NULL)
  d$measure <- m
  d$value <- trials[!is.na(trials[[m]]), m]
  d
}))

# NASA-TLX: raw = mean of the six ratings; weighted = sum(tally x rating) / 15
subs <- c("mental", "physical", "temporal", "performance", "effort", "frustration")
ratings <- as.matrix(tlx[, subs])
tallies <- as.matrix(tlx[, paste0("w_", subs)])
# tlx.csv has no group column: the participant's group comes from trials.csv
groups <- unique(trials[, c("participant", "group")])
tlx$group <- groups$group[match(tlx$participant, groups$participant)]
tlx_scores <- data.frame(tlx[, c("participant", "group", "task", "condition")],
                         tlx_raw = rowMeans(ratings),
                         tlx_weighted = rowSums(ratings * tallies) / 15,
                         setNames(as.data.frame(ratings), paste0("tlx_", subs)))
long_tlx <- do.call(rbind, lapply(setdiff(names(tlx_scores), keys), function(m) {
  d <- tlx_scores[!is.na(tlx_scores[[m]]), c("participant", "group", "task", "condition")]
  if (!nrow(d)) return(NULL)  # a study without questionnaires
  d$measure <- m
  d$value <- tlx_scores[!is.na(tlx_scores[[m]]), m]
  d
}))

# participant means: the unit of the comparisons and of the ANOVA
means <- do.call(rbind, lapply(Filter(Negate(is.null), list(long_trials, long_tlx)),
  function(d) aggregate(value ~ participant + group + task + condition + measure, d, mean)))

# differences at the data's resolution (9 significant digits of its magnitude):
# values closer than that to zero are zero, runs closer than that are one value
at_resolution <- function(d, scale) {
  tol <- 1e-9 * scale
  size <- abs(d)
  o <- order(size)
  anchor <- 0
  snapped <- size[o]
  for (i in seq_along(snapped)) {
    if (snapped[i] - anchor > tol) anchor <- snapped[i]
    snapped[i] <- anchor
  }
  size[o] <- snapped
  sign(d) * size
}

signed_rank_p <- function(d) {
  dist <- if (length(d) < 50) "exact" else "asymptotic"
  pvalue(wilcoxsign_test(y ~ x, data = data.frame(y = d, x = 0), distribution = dist))
}

# d_z's interval: the noncentrality whose t distribution has the observed t at the
# interval's quantile (the pivot of MBESS::ci.smd), by uniroot in a widening bracket
ncp_root <- function(t, df, q) {
  f <- function(ncp) pt(t, df, ncp) - q
  direction <- if (f(t) > 0) 1 else -1
  near <- t
  step <- 1
  repeat {
    far <- t + direction * step
    if ((f(far) > 0) != (f(near) > 0)) {
      return(uniroot(f, sort(c(near, far)), tol = 1e-12)$root)
    }
    near <- far
    step <- step * 2
  }
}

# the numbers of differences with a spread: t, the mean difference's CI, d_z with its
# CI, Hedges' g_av (Lakens' d_av times J = 1 - 3 / (4 (n - 1) - 1)), BF10 (JZS, r = .707)
t_parts <- function(vo, hv) {
  n <- length(vo)
  t <- t.test(hv, vo, paired = TRUE)
  stat <- unname(t$statistic)
  d_av <- (mean(hv) - mean(vo)) / ((sd(vo) + sd(hv)) / 2)
  bf <- ttestBF(x = hv, y = vo, paired = TRUE, rscale = sqrt(2) / 2)
  list(t = stat, p_t = t$p.value, diff_ci_low = t$conf.int[1], diff_ci_high = t$conf.int[2],
       dz = stat / sqrt(n), dz_ci_low = ncp_root(stat, n - 1, 0.975) / sqrt(n),
       dz_ci_high = ncp_root(stat, n - 1, 0.025) / sqrt(n),
       g_av = d_av * (1 - 3 / (4 * (n - 1) - 1)), bf10 = exp(bf@bayesFactor$bf))
}

rank_biserial <- function(d) {
  r <- rank(abs(d))
  plus <- sum(r[d > 0])
  minus <- sum(r[d < 0])
  if (plus + minus == 0) 0 else (plus - minus) / (plus + minus)
}

none <- list(t = NA, p_t = NA, diff_ci_low = NA, diff_ci_high = NA, dz = NA, dz_ci_low = NA,
             dz_ci_high = NA, g_av = NA, bf10 = NA)

compare <- function(vo, hv) {
  d <- at_resolution(hv - vo, max(abs(c(vo, hv))))
  if (all(d == d[1])) {
    if (d[1] == 0) return(c(list(test = "none", statistic = NA, p = NA, effect_size = NA),
                            none))
    return(c(list(test = "wilcoxon", statistic = sum(rank(abs(d))[d > 0]),
                  p = signed_rank_p(d), effect_size = rank_biserial(d)), none))
  }
  parts <- t_parts(vo, hv)
  if (shapiro.test(d)$p.value >= 0.05) {
    return(c(list(test = "paired_t", statistic = parts$t, p = parts$p_t,
                  effect_size = parts$g_av), parts))
  }
  c(list(test = "wilcoxon", statistic = sum(rank(abs(d))[d > 0]), p = signed_rank_p(d),
         effect_size = rank_biserial(d)), parts)
}

rows <- list()
for (cell in split(means, list(means$task, means$measure, means$group), drop = TRUE)) {
  wide <- reshape(cell[, c("participant", "condition", "value")], idvar = "participant",
                  timevar = "condition", direction = "wide")
  wide <- wide[complete.cases(wide), ]
  if (nrow(wide) < 3 || !all(c("value.VO", "value.HV") %in% names(wide))) next
  r <- compare(wide$value.VO, wide$value.HV)
  rows[[length(rows) + 1]] <- data.frame(
    task = cell$task[1], measure = cell$measure[1], group = cell$group[1],
    n = nrow(wide), test = r$test, statistic = r$statistic, p = r$p,
    effect_size = r$effect_size, mean_diff = mean(wide$value.HV - wide$value.VO),
    diff_ci_low = r$diff_ci_low, diff_ci_high = r$diff_ci_high, dz = r$dz,
    dz_ci_low = r$dz_ci_low, dz_ci_high = r$dz_ci_high, g_av = r$g_av, bf10 = r$bf10)
}
comparisons <- do.call(rbind, rows)  # NULL when no group has 3 pairs
if (is.null(comparisons)) {
  comparisons <- data.frame(task = character(), measure = character(), group = character(),
                            n = integer(), test = character(), statistic = numeric(),
                            p = numeric(), effect_size = numeric(), mean_diff = numeric(),
                            diff_ci_low = numeric(), diff_ci_high = numeric(), dz = numeric(),
                            dz_ci_low = numeric(), dz_ci_high = numeric(), g_av = numeric(),
                            bf10 = numeric())
}
# Holm within task x measure, across the testable groups
comparisons$p_holm <- if (nrow(comparisons)) {
  ave(comparisons$p, comparisons$task, comparisons$measure,
      FUN = function(p) { p[!is.na(p)] <- p.adjust(p[!is.na(p)], "holm"); p })
} else numeric()
write.csv(comparisons, file.path(out, "comparisons.csv"), row.names = FALSE)

# task success: a participant succeeded in a condition when every trial of it did; the
# exact McNemar test is the binomial test of the discordant pairs, Holm within task
if ("success" %in% names(trials)) {
  outcome <- trials[!is.na(trials$success) & trials$success != "", ]
  outcome$ok <- outcome$success %in% c(TRUE, "True", "true", "TRUE", 1, "1")
  by_block <- aggregate(ok ~ participant + group + task + condition, outcome, all)
  success_rows <- list()
  for (cell in split(by_block, list(by_block$task, by_block$group), drop = TRUE)) {
    wide <- reshape(cell[, c("participant", "condition", "ok")], idvar = "participant",
                    timevar = "condition", direction = "wide")
    if (!all(c("ok.VO", "ok.HV") %in% names(wide))) next
    wide <- wide[complete.cases(wide), ]
    if (!nrow(wide)) next
    b <- sum(wide$ok.VO & !wide$ok.HV)
    c <- sum(wide$ok.HV & !wide$ok.VO)
    success_rows[[length(success_rows) + 1]] <- data.frame(
      task = cell$task[1], group = cell$group[1], n = nrow(wide),
      success_vo = sum(wide$ok.VO), success_hv = sum(wide$ok.HV), vo_only = b, hv_only = c,
      p = if (b + c) binom.test(b, b + c)$p.value else 1)
  }
  success <- do.call(rbind, success_rows)
  if (!is.null(success)) {
    success$p_holm <- ave(success$p, success$task, FUN = function(p) p.adjust(p, "holm"))
    write.csv(success, file.path(out, "success.csv"), row.names = FALSE)
  }
}

# mixed ANOVA on participant means: group between, condition within, Type II
# (`study analyze --ss-type 3`: type = 3)
anova_rows <- list()
for (cell in split(means, list(means$task, means$measure), drop = TRUE)) {
  fit <- suppressWarnings(suppressMessages(aov_ez(
    "participant", "value", cell, between = "group", within = "condition", type = 2,
    anova_table = list(es = "pes", correction = "none"))))
  a <- as.data.frame(fit$anova_table)
  anova_rows[[length(anova_rows) + 1]] <- data.frame(
    task = cell$task[1], measure = cell$measure[1], source = rownames(a),
    F = a$F, df1 = a$`num Df`, df2 = a$`den Df`, p = a$`Pr(>F)`, np2 = a$pes)
}
write.csv(do.call(rbind, anova_rows), file.path(out, "anova.csv"), row.names = FALSE)

# the mixed model over all trials, condition VO and the first group (alphabetically)
# as references, Satterthwaite df; the condition effect as emmeans's marginal means
lmm_rows <- list()
emm_rows <- list()
for (cell in split(long_trials, list(long_trials$task, long_trials$measure), drop = TRUE)) {
  cell$condition <- relevel(factor(cell$condition), ref = "VO")
  cell$group <- factor(cell$group)
  fit <- lmer(value ~ condition * group + (1 | participant), cell, REML = TRUE)
  co <- summary(fit, ddf = "Satterthwaite")$coefficients
  lmm_rows[[length(lmm_rows) + 1]] <- data.frame(
    task = cell$task[1], measure = cell$measure[1], term = rownames(co),
    estimate = co[, "Estimate"], se = co[, "Std. Error"], df = co[, "df"],
    t = co[, "t value"], p = co[, "Pr(>|t|)"])
  e <- suppressMessages(emmeans(fit, ~ condition, lmer.df = "satterthwaite"))
  m <- summary(e, infer = TRUE)
  pr <- summary(pairs(e, reverse = TRUE), infer = TRUE)
  emm_rows[[length(emm_rows) + 1]] <- data.frame(
    task = cell$task[1], measure = cell$measure[1],
    term = c(paste("mean", m$condition), "HV - VO"),
    estimate = c(m$emmean, pr$estimate), se = c(m$SE, pr$SE), df = c(m$df, pr$df),
    p = c(NA, NA, pr$p.value))
}
write.csv(do.call(rbind, lmm_rows), file.path(out, "lmm.csv"), row.names = FALSE)
write.csv(do.call(rbind, emm_rows), file.path(out, "emmeans.csv"), row.names = FALSE)

# the crossover's checks, on the trials: each participant's blocks of a task are its
# periods in the order run; `later` = a block after the first, `carry` = VO in a later
# block than HV, `pos` = the trial's place in its block, centred within the block. The
# period and the trial position are tested beside each other, the carry-over beside
# both; a term aliased with the rest of the model is not testable (not reported).
ctl <- lmerControl(optimizer = "bobyqa",
                   optCtrl = list(rhobeg = 2e-4, rhoend = 1e-12, maxfun = 1e5))
check_rows <- list()
for (cell in split(long_trials, list(long_trials$task, long_trials$measure), drop = TRUE)) {
  if (length(unique(cell$participant)) < 3) next
  cell$condition <- relevel(factor(cell$condition), ref = "VO")
  cell$group <- factor(cell$group)
  cell$period <- ave(cell$block, cell$participant,
                     FUN = function(b) match(b, sort(unique(b))))
  cell$later <- as.numeric(cell$period > 1)
  cell$carry <- cell$later * (cell$condition == "VO")
  cell$pos <- cell$trial - ave(cell$trial, cell$participant, cell$period)
  base <- "value ~ condition * group"
  full_rank <- function(terms) {
    X <- model.matrix(as.formula(paste(base, paste(c("", terms), collapse = " + "))), cell)
    qr(X)$rank == ncol(X)
  }
  testable <- c(period = full_rank("later"), carry_over = full_rank(c("later", "carry")),
                trial_position = max(cell$trial) >= 2)
  term <- c(period = "later", carry_over = "carry", trial_position = "pos")
  for (effect in names(term)[testable]) {
    terms <- term[names(term)[testable]]
    if (effect != "carry_over") terms <- terms[names(terms) != "carry_over"]
    fit <- lmer(as.formula(paste(base, "+", paste(terms, collapse = " + "),
                                 "+ (1 | participant)")), cell, REML = TRUE, control = ctl)
    co <- summary(fit, ddf = "Satterthwaite")$coefficients[term[[effect]], ]
    df <- co[["df"]]
    if (effect != "carry_over" && isSingular(fit)) {
      # a singular fit's pooled residual is too small for a within-participant term:
      # test it against the within-participant residual (participants as fixed effects)
      within <- lm(as.formula(paste(base, "+ participant +", paste(terms, collapse = " + "))),
                   cell)
      co <- summary(within)$coefficients[term[[effect]], ]
      df <- within$df.residual
    }
    check_rows[[length(check_rows) + 1]] <- data.frame(
      task = cell$task[1], measure = cell$measure[1], effect = effect,
      estimate = co[["Estimate"]], df = df, p = co[["Pr(>|t|)"]])
  }
}
checks <- do.call(rbind, check_rows)
checks$p_holm <- p.adjust(checks$p, "holm")
checks$added <- checks$p_holm < 0.05
write.csv(checks, file.path(out, "design_checks.csv"), row.names = FALSE)
cat("written to", out, "\n")
