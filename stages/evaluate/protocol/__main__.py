from stages.evaluate.protocol.cli import main

main()
