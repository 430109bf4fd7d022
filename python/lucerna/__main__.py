"""`python -m lucerna ...`: the lucerna command line."""

from lucerna import main

main()
