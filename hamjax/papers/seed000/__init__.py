"""Seed 000 (Brouri, Giri, Rochdi, Chaoui): the Fig. 6 plant, the border shapes of
Figs. 2-4 and Remark 1b, the reproduction of Figs. 5-6, and the studies of
Propositions 1-2 (`studies/`). NBBI and FGI are `hamjax/identification/seed000/`."""
