"""Error budgets and their propagation: the paper's presets, the 22x22 parameter covariance and
its PSD factor (:mod:`.budget`), linear / Monte Carlo / unscented propagation with the linearity
flag (:mod:`.propagation`), and ellipse geometry (:mod:`.ellipse`)."""
