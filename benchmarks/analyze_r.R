# The analysis `study analyze` runs, in R, on the participant means of a study (the CSV
# `benchmarks/analyze_vs_r.py` writes from the database: participant, group, task,
# condition, measure, value): per measure the mixed ANOVA (afex, Type II, partial eta^2),
# the mixed model with a random intercept per participant (lmerTest, Satterthwaite df),
# and per group the paired t test and the exact Wilcoxon signed-rank test, Holm-corrected.
#   Rscript benchmarks/analyze_r.R MEANS.csv OUT.txt
args <- commandArgs(trailingOnly = TRUE)
suppressPackageStartupMessages({
  library(afex)
  library(lmerTest)
})
d <- read.csv(args[1])
out <- file(args[2], "w")
for (m in unique(d$measure)) {
  s <- d[d$measure == m, ]
  s$group <- factor(s$group)
  s$condition <- factor(s$condition, levels = c("VO", "HV"))
  a <- aov_ez("participant", "value", s, between = "group", within = "condition",
              type = 2, anova_table = list(es = "pes", correction = "none"))
  writeLines(c(m, capture.output(print(a$anova_table, digits = 12))), out)
  fit <- lmer(value ~ group * condition + (1 | participant), data = s, REML = TRUE)
  writeLines(capture.output(print(anova(fit)), print(summary(fit)$coefficients)), out)
  p <- c()
  for (g in unique(s$group)) {
    w <- reshape(s[s$group == g, c("participant", "condition", "value")],
                 idvar = "participant", timevar = "condition", direction = "wide")
    tt <- t.test(w$value.HV, w$value.VO, paired = TRUE)
    wt <- suppressWarnings(wilcox.test(w$value.HV, w$value.VO, paired = TRUE, exact = TRUE))
    p <- c(p, tt$p.value, wt$p.value)
    writeLines(sprintf("%s %s t=%.12g p=%.12g V=%g p=%.12g", m, g, tt$statistic,
                       tt$p.value, wt$statistic, wt$p.value), out)
  }
  writeLines(sprintf("holm %s", paste(format(p.adjust(p, "holm"), digits = 12), collapse = " ")), out)
}
close(out)
