"""Seed 001 (Giri, Rochdi, Chaoui): the Section V.C plant and random ones, the
reproduction of Section V.C (Fig. 3), and the studies of Propositions 5.1-5.2
(`studies/`). The procedure is `hamjax/identification/seed001/`."""
